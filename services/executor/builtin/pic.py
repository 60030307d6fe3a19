"""`pic`: the seed's take-a-photo tutorial. After the optional `wait` seconds, save the
next camera frame through the bridge: a sensor_msgs/Image as a PNG, a CompressedImage as
the file it carries (JPEG, PNG)."""

from __future__ import annotations

import asyncio
import io
import time
from pathlib import Path
from typing import Annotated

import msgspec
from PIL import Image as PilImage

from voicectl.shared.errors import OrderFailed
from voicectl.shared.messages import Order
from voicectl.shared.ros2 import CompressedImage, Image

from ..framework import ExecutionContext, Executor

# sensor_msgs/Image encodings Pillow can take as they are, with the channel order to use.
_MODES = {
    "rgb8": ("RGB", "RGB"),
    "bgr8": ("RGB", "BGR"),
    "rgba8": ("RGBA", "RGBA"),
    "bgra8": ("RGBA", "BGRA"),
    "mono8": ("L", "L"),
}


_SUFFIXES = {"JPEG": ".jpg", "PNG": ".png", "TIFF": ".tiff"}
"""File suffixes of the formats Pillow finds in a CompressedImage (others: its name)."""


class Delay(msgspec.Struct):
    wait: Annotated[float, msgspec.Meta(ge=0)] = 0.0
    """Seconds before the photo is taken."""


class TakePhoto(Executor):
    labels = ("pic",)
    params_type = Delay

    def __init__(self, directory: Path | str) -> None:
        self.directory = Path(directory).expanduser()

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        wait = ctx.params.wait
        for left in range(int(wait), 0, -1):
            ctx.progress(f"photo in {left} s", percent=100.0 * (wait - left) / wait)
            await asyncio.sleep(1.0)
        await asyncio.sleep(wait - int(wait))
        frame = await ctx.robot.next_image()
        stem = self.directory / f"{time.strftime('%Y%m%d-%H%M%S')}-{ctx.order_id}"
        if isinstance(frame, CompressedImage):
            path, (width, height) = await asyncio.to_thread(_save_file, frame, stem)
        else:
            path = stem.with_suffix(".png")
            width, height = frame.width, frame.height
            await asyncio.to_thread(_save_png, frame, path)
        return f"took a {width}x{height} photo (kept on the robot as {path})"


def _save_file(frame: CompressedImage, stem: Path) -> tuple[Path, tuple[int, int]]:
    """Write the compressed file as it came, named by what it holds (the format string
    is the robot's to fill); where it went, and its size in pixels."""
    try:
        with PilImage.open(io.BytesIO(frame.data)) as picture:
            kind, size = str(picture.format), picture.size
    except (OSError, ValueError) as exc:
        raise OrderFailed(f"the camera's {frame.format!r} frame does not open: {exc}") from None
    path = stem.with_suffix(_SUFFIXES.get(kind, f".{kind.lower()}"))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(frame.data)
    return path, size


def _save_png(frame: Image, path: Path) -> None:
    if frame.encoding not in _MODES:
        raise OrderFailed(
            f"camera encoding {frame.encoding!r} is not supported; supported: {', '.join(_MODES)}"
        )
    mode, raw_mode = _MODES[frame.encoding]
    picture = PilImage.frombytes(mode, (frame.width, frame.height), frame.data, "raw", raw_mode)
    path.parent.mkdir(parents=True, exist_ok=True)
    picture.save(path, format="PNG")
