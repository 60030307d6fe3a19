"""The session helper over a real Zenoh router on loopback."""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from typing import cast

import msgspec
import pytest
import zenoh

from harness.wait import async_wait_until
from voicectl.shared.bus import BusOptions, Pending, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.messages import (
    Done,
    EmergencyStop,
    ExecutorEvent,
    Failed,
    GetState,
    Message,
    OrderFinished,
    OrderStatus,
    Submit,
    SupervisorRequest,
    Transcript,
)
from voicectl.shared.wire import MATCHING_RECHECK

from .support import joined, until_heard


def options(router: str) -> BusOptions:
    return BusOptions(connect=[router])


async def test_publish_subscribe_decodes_and_drops_junk(
    router: str, caplog: pytest.LogCaptureFixture
) -> None:
    received: list[tuple[str, Transcript]] = []
    with (
        caplog.at_level(logging.WARNING, logger="voicectl.shared.wire"),
        joined(router) as sub,
        joined(router) as pub,
    ):
        sub.subscribe(
            "voice/*/stt/transcript",
            json_decoder(Transcript),
            lambda key, msg: received.append((key, msg)),
        )
        await until_heard(pub, "voice/r1/stt/transcript")
        pub.session.put("voice/r1/stt/transcript", b"\xff not json")
        for _ in range(1000):  # anyone on the bus can: said once, not a thousand times
            pub.session.put("voice/r1/stt/transcript", b'{"type": "transcript"}')
        pub.publish("voice/r1/stt/transcript", Transcript(text="turn left"))
        await async_wait_until(lambda: received, 5.0, "a transcript")
    assert received == [("voice/r1/stt/transcript", Transcript(text="turn left"))]
    dropped = [r.getMessage() for r in caplog.records if "undecodable" in r.getMessage()]
    assert dropped == [
        "dropped undecodable message on voice/r1/stt/transcript: "
        "JSON is malformed: invalid character (byte 0)"
    ]


async def test_json_on_the_wire_is_readable_by_any_tool(router: str) -> None:
    got: list[zenoh.Sample] = []
    with joined(router) as bus:
        subscriber = bus.session.declare_subscriber("voice/**", got.append)  # same session
        bus.publish("voice/r1/stt/transcript", Transcript(text="hi"))
        await async_wait_until(lambda: got, 5.0, "the raw sample")
        subscriber.undeclare()
    payload, encoding = got[0].payload.to_bytes(), str(got[0].encoding)
    assert payload.startswith(b'{"type":"transcript","text":"hi",')
    assert json.loads(payload)["rejected"] is False
    assert encoding == "application/json"


async def test_request_reply_and_errors(router: str) -> None:
    with joined(router) as server, joined(router) as client:

        async def handle(request: SupervisorRequest) -> Message:
            match request:
                case GetState():
                    return Done(detail="state")
                case _:
                    raise RuntimeError("boom")

        server.serve("voice/r1/supervisor/request", json_decoder(SupervisorRequest), handle)
        decode = json_decoder(Done | Failed)
        served: list[bool] = []
        # A queryable's until_heard: the request goes once the router has it.
        client.watch_served("voice/r1/supervisor/request", served.append)
        await async_wait_until(lambda: served[-1:] == [True], 10.0, "the queryable")
        reply = await client.request("voice/r1/supervisor/request", GetState(), decode)
        assert reply == Done(detail="state")
        raw = await client.request_bytes("voice/r1/supervisor/request", b"junk", 5.0)
        assert b"undecodable request" in raw
        failed = await client.request(
            "voice/r1/supervisor/request",
            Transcript(text="not a request"),
            decode,
        )
        assert isinstance(failed, Failed)
        with pytest.raises(BusError, match="no service answered"):
            await client.request("voice/r2/supervisor/request", GetState(), decode, 1.0)


async def test_a_served_watch_tells_each_change_once_though_it_reads_it_again(
    router: str,
) -> None:
    key = "voice/r1/executor/control"
    served: list[bool] = []
    with joined(router) as client:
        client.watch_served(key, served.append)
        await async_wait_until(lambda: served == [False], 5.0, "the first status")
        with joined(router) as server:

            async def handle(_request: SupervisorRequest) -> Message:
                return Done(detail="")

            server.serve(key, json_decoder(SupervisorRequest), handle)
            await async_wait_until(lambda: served == [False, True], 10.0, "the queryable")
            # read again every MATCHING_RECHECK seconds, told only when it changes
            await asyncio.sleep(MATCHING_RECHECK * 2.5)
            assert served == [False, True]
        await async_wait_until(lambda: served == [False, True, False], 10.0, "it to go")


async def test_liveliness_tokens_come_and_go(router: str) -> None:
    seen: list[bool] = []
    with joined(router) as watcher:
        watcher.watch("voice/r1/alive/executor", lambda _key, alive: seen.append(alive))
        with joined(router) as service:
            service.announce("voice/r1/alive/executor")
            await async_wait_until(lambda: seen == [True], 5.0, "the token")
        await async_wait_until(lambda: seen == [True, False], 5.0, "the token to go")
    assert seen == [True, False]


def test_an_order_cannot_finish_as_queued_or_running() -> None:
    decode = json_decoder(ExecutorEvent)
    finished = decode(b'{"type": "orderfinished", "order_id": "a", "status": "failed"}')
    assert finished == OrderFinished(order_id="a", status=OrderStatus.FAILED)
    for status in ("queued", "running"):
        raw = f'{{"type": "orderfinished", "order_id": "a", "status": "{status}"}}'.encode()
        with pytest.raises(msgspec.ValidationError, match=f"an order does not finish as {status}"):
            decode(raw)


async def test_serve_in_turn_takes_a_burst_at_once_in_order_and_stop_overtakes(
    router: str,
) -> None:
    key = "voice/r1/supervisor"
    log: list[str] = []
    arrived = threading.Semaphore(0)
    taken: list[Pending[SupervisorRequest]] = []
    release = asyncio.Event()
    answers: list[str] = []  # appended on Zenoh's threads

    def overtakes(request: SupervisorRequest) -> bool:  # on Zenoh's thread, once a request
        arrived.release()
        return isinstance(request, EmergencyStop)

    def take(batch: list[Pending[SupervisorRequest]]) -> None:
        log.append("take " + " ".join(cast(Submit, p.request).request_id for p in batch))
        taken.extend(batch)

    async def handle(_key: str, request: SupervisorRequest) -> Message:
        name = type(request).__name__
        log.append(name)
        if isinstance(request, GetState):
            await release.wait()
        return Done(detail=name)

    def on_reply(reply: zenoh.Reply) -> None:
        assert reply.ok is not None
        answers.append(json.loads(reply.ok.payload.to_bytes())["detail"])

    with joined(router) as server, joined(router) as client:
        server.serve_in_turn(
            key,
            json_decoder(SupervisorRequest),
            handle,
            batched=lambda request: isinstance(request, Submit),
            take=take,
            overtakes=overtakes,
        )
        served: list[bool] = []
        client.watch_served(key, served.append)
        await async_wait_until(lambda: served[-1:] == [True], 10.0, "the queryable")
        sent = [
            Submit(request_id="a", orders=[]),
            Submit(request_id="b", orders=[]),
            GetState(),
            Submit(request_id="c", orders=[]),
            EmergencyStop(),
        ]
        for message in sent:
            client.session.get(key, on_reply, payload=client.encode(message))
        # The loop is held here (on purpose) until all five have arrived: one burst.
        for _ in sent:
            assert arrived.acquire(timeout=10)
        await async_wait_until(lambda: answers, 10.0, "the stop's answer")
        # The stop was answered while the submits before it and the state were not.
        assert answers == ["EmergencyStop"]
        # One call for the submits before the state request, the state request's handler
        # started before the submit after it, and the stop waited for neither.
        assert log == ["take a b", "GetState", "EmergencyStop", "take c"]

        release.set()
        answering = threading.Thread(target=lambda: [p.answer(Done(detail="x")) for p in taken])
        answering.start()
        await async_wait_until(lambda: len(answers) == 5, 10.0, "every answer")
        answering.join()
    assert sorted(answers) == ["EmergencyStop", "GetState", "x", "x", "x"]
