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
import queue
import threading
import uuid
from collections.abc import Callable, MutableMapping
from typing import Annotated, Any

import msgspec
from starlette.websockets import WebSocket, WebSocketDisconnect

from voicectl.shared.bus import Bus, Stream
from voicectl.shared.keys import RobotKeys, check_chunk
from voicectl.shared.messages import (
    FRAME_BYTES,
    MAX_CHUNK_FRAMES,
    AudioChunk,
    AudioMessage,
    AudioStart,
    AudioStop,
    SessionEnded,
)

_LOGGER = logging.getLogger(__name__)

HELLO_TIMEOUT = 5.0
MATCH_TIMEOUT = 3.0
"""How long to wait for the recogniser to be subscribed before telling the browser so."""
MAX_MESSAGE = FRAME_BYTES * MAX_CHUNK_FRAMES
QUEUED = 100
"""Audio messages that may wait for the bus before new ones are dropped (2 s of 20 ms)."""

# WebSocket close codes (4000-4999 are the application's).
NORMAL = 1000
UNAUTHORISED = 4401
FORBIDDEN = 4403
UNAVAILABLE = 4503
BAD_DATA = 1003
TOO_BIG = 1009


class Hello(msgspec.Struct, forbid_unknown_fields=True):
    token: str
    robot: str
    language: Annotated[str, msgspec.Meta(pattern="^([a-z]{2,3})?$")] = ""
    """What the person speaks (the panel's language); empty: the recogniser's own."""


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
        self._ended = msgspec.json.Decoder(SessionEnded).decode

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
            await self._bridge(websocket, *robot)

    async def _greet(self, websocket: WebSocket) -> tuple[str, str] | None:
        """The robot and the language the first message names, once its token is right;
        else None."""
        async with asyncio.timeout(HELLO_TIMEOUT):
            message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(message.get("code", 1000))
        text = message.get("text")
        if text is None:  # audio before the greeting, or a greeting sent as bytes
            await _refuse(websocket, BAD_DATA, "first message must be text: {token, robot}")
            return None
        try:
            hello = self._hello.decode(text)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            await _refuse(websocket, BAD_DATA, f"first message must be {{token, robot}}: {exc}")
            return None
        if not self._token_ok(hello.token):
            await _refuse(websocket, UNAUTHORISED, "missing or wrong token")
            return None
        try:
            return check_chunk(hello.robot, "robot name"), hello.language
        except ValueError as exc:
            await _refuse(websocket, BAD_DATA, str(exc))
            return None

    async def _bridge(self, websocket: WebSocket, robot: str, language: str = "") -> None:
        session = uuid.uuid4().hex[:16]
        keys = RobotKeys(robot)
        bus = self._bus()
        stream = _Sender(bus.stream(keys.stt_audio(session)), session)
        # The recogniser may refuse the session (too many open) or end it (idle): heard
        # here before the start goes out, and told to the browser in words.
        ended: asyncio.Future[SessionEnded] = asyncio.get_running_loop().create_future()

        def on_ended(_key: str, message: SessionEnded) -> None:
            if not ended.done():
                ended.set_result(message)

        unsubscribe = bus.subscribe(keys.stt_session(session), self._ended, on_ended)
        receiving: asyncio.Future[MutableMapping[str, Any]] | None = None
        try:
            if not await stream.matched(MATCH_TIMEOUT):
                await _refuse(websocket, UNAVAILABLE, "speech recognition is not running")
                return
            stream.send(AudioStart(language=language))
            await websocket.send_json({"type": "session", "session": session})
            _LOGGER.info("audio session %s for %s opened", session, robot)
            seq = 0
            while True:
                receiving = asyncio.ensure_future(websocket.receive())
                either: set[asyncio.Future[Any]] = {receiving, ended}
                await asyncio.wait(either, return_when=asyncio.FIRST_COMPLETED)
                if ended.done():
                    told = ended.result()
                    await _refuse(websocket, UNAVAILABLE if told.refused else NORMAL, told.reason)
                    break
                message = receiving.result()
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
            if receiving is not None and not receiving.done():
                receiving.cancel()
            unsubscribe()
            stream.send(AudioStop())
            stream.close()
            _LOGGER.info("audio session %s for %s closed", session, robot)


class _Sender:
    """A session's audio, put on the bus from a thread of its own: a put that waits for
    room under congestion must never hold up the event loop the panel's STOP is served
    on. Past `QUEUED` waiting messages, new chunks are dropped (said once in the log);
    the session's start and stop are never dropped."""

    def __init__(self, stream: Stream, session: str) -> None:
        self._stream = stream
        self._session = session
        self._queue: queue.Queue[AudioMessage | None] = queue.Queue()
        self._dropped = 0
        self._thread = threading.Thread(target=self._run, name=f"audio-{session}", daemon=True)
        self._thread.start()

    async def matched(self, timeout: float) -> bool:
        return await self._stream.matched(timeout)

    def send(self, message: AudioMessage) -> None:
        if isinstance(message, AudioChunk) and self._queue.qsize() >= QUEUED:
            self._dropped += 1
            if self._dropped == 1:
                _LOGGER.warning(
                    "audio session %s: the bus is congested; dropping audio", self._session
                )
            return
        self._queue.put_nowait(message)

    def close(self) -> None:
        """Send what is queued, then close the stream (on the sender's thread)."""
        self._queue.put_nowait(None)
        if self._dropped:
            _LOGGER.warning("audio session %s: %d chunks dropped", self._session, self._dropped)

    def _run(self) -> None:
        while (message := self._queue.get()) is not None:
            self._stream.send(message)
        self._stream.close()


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
