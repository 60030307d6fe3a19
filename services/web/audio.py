"""The browser's microphone to the recogniser: one WebSocket, one audio session on the bus.

A browser cannot put a token in a WebSocket's headers, and a URL would end up in logs, so
the first message says who it is: ``{"token": ..., "robot": ...}``. Until it does nothing
is forwarded; a wrong token closes the socket with code 4401. Then every binary message is
whole 20 ms frames of 16 kHz mono 16-bit PCM, forwarded as they come; ``{"type":
"stop"}`` or closing the socket ends the session. The server answers with JSON:
``{"type": "session", "session": ID}`` first (the panel picks its own transcripts out of
the event stream by that id), and ``{"type": "error", "error": ...}`` before it closes
for a reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from collections.abc import Callable

import msgspec
from starlette.websockets import WebSocket, WebSocketDisconnect

from shared.bus import Bus
from shared.keys import RobotKeys, check_chunk
from shared.messages import FRAME_BYTES, MAX_CHUNK_FRAMES, AudioChunk, AudioStart, AudioStop

_LOGGER = logging.getLogger(__name__)

HELLO_TIMEOUT = 5.0
MATCH_TIMEOUT = 3.0
"""How long to wait for the recogniser to be subscribed before telling the browser so."""
MAX_MESSAGE = FRAME_BYTES * MAX_CHUNK_FRAMES

# WebSocket close codes (4000-4999 are the application's).
UNAUTHORISED = 4401
FORBIDDEN = 4403
UNAVAILABLE = 4503
BAD_DATA = 1003
TOO_BIG = 1009


class Hello(msgspec.Struct, forbid_unknown_fields=True):
    token: str
    robot: str


class AudioSocket:
    """Serves /api/audio: checks Origin and token, then bridges frames to the bus."""

    def __init__(
        self,
        bus: Callable[[], Bus],
        token_ok: Callable[[str], bool],
        origin_ok: Callable[[WebSocket], bool],
    ) -> None:
        self._bus = bus
        """The app's bus, which exists once the app has started."""
        self._token_ok = token_ok
        self._origin_ok = origin_ok
        self._hello = msgspec.json.Decoder(Hello)

    async def serve(self, websocket: WebSocket) -> None:
        if not self._origin_ok(websocket):
            _LOGGER.warning("audio socket refused: origin %r", websocket.headers.get("origin"))
            await websocket.close(code=FORBIDDEN, reason="origin not allowed")
            return
        await websocket.accept()
        try:
            robot = await self._greet(websocket)
        except TimeoutError:
            await _refuse(websocket, UNAUTHORISED, f"no token within {HELLO_TIMEOUT:g} s")
            return
        except WebSocketDisconnect:
            return
        if robot is not None:
            await self._bridge(websocket, robot)

    async def _greet(self, websocket: WebSocket) -> str | None:
        """The robot the first message names, once its token is right; else None."""
        text = await asyncio.wait_for(websocket.receive_text(), HELLO_TIMEOUT)
        try:
            hello = self._hello.decode(text)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            await _refuse(websocket, BAD_DATA, f"first message must be {{token, robot}}: {exc}")
            return None
        if not self._token_ok(hello.token):
            await _refuse(websocket, UNAUTHORISED, "missing or wrong token")
            return None
        try:
            return check_chunk(hello.robot, "robot name")
        except ValueError as exc:
            await _refuse(websocket, BAD_DATA, str(exc))
            return None

    async def _bridge(self, websocket: WebSocket, robot: str) -> None:
        session = uuid.uuid4().hex[:16]
        stream = self._bus().stream(RobotKeys(robot).stt_audio(session))
        try:
            if not await stream.matched(MATCH_TIMEOUT):
                await _refuse(websocket, UNAVAILABLE, "speech recognition is not running")
                return
            stream.send(AudioStart())
            await websocket.send_json({"type": "session", "session": session})
            _LOGGER.info("audio session %s for %s opened", session, robot)
            seq = 0
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                pcm = message.get("bytes")
                if pcm is None:
                    if _is_stop(message.get("text")):
                        await websocket.close()
                        break
                    await _refuse(websocket, BAD_DATA, 'expected audio frames or {"type": "stop"}')
                    break
                if len(pcm) > MAX_MESSAGE:
                    await _refuse(websocket, TOO_BIG, f"at most {MAX_MESSAGE} bytes per message")
                    break
                if not pcm or len(pcm) % FRAME_BYTES:
                    await _refuse(
                        websocket, BAD_DATA, f"audio must be whole {FRAME_BYTES}-byte frames"
                    )
                    break
                stream.send(AudioChunk(seq=seq, pcm=pcm))
                seq += 1
        except WebSocketDisconnect:
            pass
        finally:
            stream.send(AudioStop())
            stream.close()
            _LOGGER.info("audio session %s for %s closed", session, robot)


def _is_stop(text: str | None) -> bool:
    if text is None:
        return False
    with contextlib.suppress(msgspec.DecodeError):
        decoded = msgspec.json.decode(text)
        return isinstance(decoded, dict) and decoded.get("type") == "stop"
    return False


async def _refuse(websocket: WebSocket, code: int, reason: str) -> None:
    """Say why in a message the page can show, then close with `code`."""
    with contextlib.suppress(RuntimeError, WebSocketDisconnect):
        await websocket.send_json({"type": "error", "error": reason})
        await websocket.close(code=code, reason=reason[:120])
