"""`pic`: the seed's take-a-photo tutorial. After the optional `wait` seconds, save the
next camera frame (sensor_msgs/Image through the bridge) as a PNG."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from PIL import Image as PilImage

from shared.errors import OrderFailed
from shared.messages import Order
from shared.ros2 import Image

from ..framework import ExecutionContext, Executor

# sensor_msgs/Image encodings Pillow can take as they are, with the channel order to use.
_MODES = {
    "rgb8": ("RGB", "RGB"),
    "bgr8": ("RGB", "BGR"),
    "rgba8": ("RGBA", "RGBA"),
    "bgra8": ("RGBA", "BGRA"),
    "mono8": ("L", "L"),
}


class TakePhoto(Executor):
    labels = ("pic",)

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        wait = order.params.get("wait", 0)
        if isinstance(wait, bool) or not isinstance(wait, int | float) or wait < 0:
            raise OrderFailed(f"'{order.description}': 'wait' must be a number of seconds >= 0")
        for left in range(int(wait), 0, -1):
            ctx.progress(f"photo in {left} s", percent=100.0 * (wait - left) / wait)
            await asyncio.sleep(1.0)
        await asyncio.sleep(wait - int(wait))
        frame = await ctx.robot.next_image()
        path = self.directory / f"{time.strftime('%Y%m%d-%H%M%S')}-{ctx.order_id}.png"
        await asyncio.to_thread(_save_png, frame, path)
        return f"saved {frame.width}x{frame.height} photo to {path}"


def _save_png(frame: Image, path: Path) -> None:
    if frame.encoding not in _MODES:
        raise OrderFailed(
            f"camera encoding {frame.encoding!r} is not supported; supported: {', '.join(_MODES)}"
        )
    mode, raw_mode = _MODES[frame.encoding]
    picture = PilImage.frombytes(mode, (frame.width, frame.height), frame.data, "raw", raw_mode)
    path.parent.mkdir(parents=True, exist_ok=True)
    picture.save(path, format="PNG")
