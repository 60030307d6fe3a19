"""The photos orders took, served to the panel on the executor's photo key: a photo is a
file on the robot, which a person's phone cannot open by its path."""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path

from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import Failed, GetPhoto, Photo, PhotoReply

_LOGGER = logging.getLogger(__name__)

MEDIA_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".tiff": "image/tiff"}
"""What the `pic` executor writes (builtin/pic.py), by suffix."""


class PhotoShelf:
    """Answers `GetPhoto` from `directory`, where `pic` names each photo after its order
    (`<time>-<order id>.<suffix>`)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    def serve(self, bus: Bus, keys: RobotKeys) -> None:
        bus.serve(keys.executor_photo, json_decoder(GetPhoto), self.answer)

    async def answer(self, request: GetPhoto) -> PhotoReply:
        order_id = request.order_id
        if not (order_id.isascii() and order_id.isalnum()):  # it goes into a file pattern
            return Failed(reason=f"no order {order_id!r}: an order id is letters and digits")
        return await asyncio.to_thread(self._read, order_id)

    def _read(self, order_id: str) -> PhotoReply:
        found = sorted(
            path
            for path in self.directory.glob(f"*-{order_id}.*")
            if path.suffix.lower() in MEDIA_TYPES
        )
        if not found:
            return Failed(reason=f"order {order_id} took no photo kept on this robot")
        try:
            data = found[-1].read_bytes()
        except OSError as exc:
            _LOGGER.warning("photo of order %s unreadable: %s", order_id, exc)
            return Failed(reason=f"the photo of order {order_id} cannot be read: {exc.strerror}")
        return Photo(order_id=order_id, media_type=MEDIA_TYPES[found[-1].suffix.lower()], data=data)
