"""Talking to the robot about its work, through the whole stack (docs/orders.md, "Talking
about the queue"): every edit and question typed with `voicectl say` and spoken into
`voicectl listen`; a correction replaces, never adds; undo restores the queue exactly; an
edit naming an order that is not in the queue changes nothing and says so; edits survive
a supervisor restart, and can still be undone after it."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest

from harness.client import STARTING
from harness.wait import async_wait_until, wait_until
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.shared.bus import Bus
from voicectl.shared.client import Sent, VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.messages import (
    Asked,
    GetHistory,
    GetState,
    HistoryPage,
    OrderRecord,
    OrderStatus,
    State,
    StateReply,
    Via,
)

from .conftest import REPO, Processes, Speak, Stack
from .support import Site, on_bus
from .test_docs import block_after
from .test_listen import VOICE, Mouth

pytestmark = pytest.mark.e2e

ORDERS = REPO / "orders"
PARSER = Parser(OrderSet.load(ORDERS))


def queued(known: State) -> list[tuple[str, str]]:
    """The waiting orders: id and words, in the order they will run."""
    return [(record.id, record.order.description) for record in known.queue]


def words(known: State) -> list[str]:
    return [record.order.description for record in known.queue]


# --- typed: `voicectl say` ---------------------------------------------------------------


def say(stack: Stack, text: str, code: int = 0) -> list[str]:
    """`voicectl say TEXT`: the answers it printed, after checking its exit status."""
    done = stack.voicectl("say", "--connect", stack.router, text)
    assert done.returncode == code, (text, done.stdout, done.stderr)
    printed = json.loads(done.stdout)
    said = [answer["answer"] for answer in printed["answers"]]
    for answer in said:  # and for a person, on stderr
        assert f"voicectl say: {answer}" in done.stderr
    return said


def state(stack: Stack) -> State:
    async def ask(bus: Bus) -> State:
        reply = await VoicectlClient(bus).ask("robot", GetState())
        assert isinstance(reply, StateReply)
        return reply.state

    return on_bus(stack.router, ask)


def test_every_edit_and_question_typed(stack: Stack) -> None:
    assert say(stack, "pause") == ["paused; 0 waiting"]
    say(stack, "reach the kitchen then reach the bathroom then reach base")
    first = state(stack)
    assert words(first) == ["reach kitchen", "reach bathroom", "reach base"]
    assert say(stack, "what are you doing") == ["nothing: 3 orders wait until you say go on"]
    assert say(stack, "where are you going") == ["nowhere: 3 orders wait until you say go on"]
    assert say(stack, "how many are left") == ["3 waiting until you say go on"]
    assert say(stack, "what is next") == ["next: reach kitchen, then 2 more"]
    assert say(stack, "how far is it") == [
        "I am not going anywhere: 3 orders wait until you say go on"
    ]
    assert say(stack, "where are you") == ["at the base"]
    assert say(stack, "why did that fail") == ["nothing has failed lately"]

    # A name not in the queue: answered, and nothing changes.
    assert say(stack, "cancel the dumpster", code=1) == ["there is no dumpster in the queue"]
    assert say(stack, "do the dumpster first", code=1) == ["there is no dumpster in the queue"]
    assert queued(state(stack)) == queued(first)

    assert say(stack, "cancel the bathroom") == ["cancelled reach bathroom; 2 left"]
    assert words(state(stack)) == ["reach kitchen", "reach base"]
    assert say(stack, "undo") == ["undone: cancel bathroom"]
    assert queued(state(stack)) == queued(first)  # the same orders, ids and places

    assert say(stack, "do base first") == ["reach base is next; 3 left"]
    assert say(stack, "after that go to the dumpster") == ["reach dumpster comes after reach base"]
    assert words(state(stack)) == [
        "reach base",
        "reach dumpster",
        "reach kitchen",
        "reach bathroom",
    ]
    # corrections replace the order named, or the last one added, where it stands
    assert say(stack, "no the kitchen") == ["now reach kitchen, not reach dumpster"]
    assert say(stack, "not the bathroom the dumpster") == ["now reach dumpster, not reach bathroom"]
    assert words(state(stack)) == ["reach base", "reach kitchen", "reach kitchen", "reach dumpster"]
    assert say(stack, "cancel the last one") == ["cancelled reach dumpster; 3 left"]
    assert say(stack, "no cancel that") == ["cancelled reach kitchen; 2 left"]
    assert say(stack, "clear the queue") == ["cleared 2 orders"]  # typed: no read-back
    assert words(state(stack)) == []
    for _ in range(7):  # every edit since the first undo, newest first
        say(stack, "undo")
    assert queued(state(stack)) == queued(first)

    # In the same breath, a correction replaces the order said before it.
    say(stack, "cancel everything")
    assert say(stack, "wait five seconds no twenty") == []
    assert words(state(stack)) == ["wait 20 s"]
    say(stack, "wait sixty seconds")
    first_wait, long_wait = state(stack).queue
    assert say(stack, "go on") == ["going on; 2 left"]
    wait_until(lambda: state(stack).current is not None, 30.0, "the first wait to run")
    assert say(stack, "what are you doing") == ["I am waiting 20 seconds, 1 more after it"]
    assert say(stack, "skip this one") == ["skipped wait 20 seconds; next: wait 60 seconds"]
    wait_until(
        lambda: (state(stack).current or first_wait).id == long_wait.id, 30.0, "the next one"
    )
    assert say(stack, "how many are left") == ["1 left: wait 60 seconds now"]
    assert say(stack, "pause") == ["pausing after wait 60 seconds; 0 waiting"]
    assert say(stack, "skip it") == ["skipped wait 60 seconds; nothing left"]
    wait_until(lambda: state(stack).current is None, 30.0, "the skipped wait to end")
    history = state(stack).history
    # the edit and the order it stopped, in whichever order the executor's word came
    assert {(r.order.description, r.status) for r in history[:2]} == {
        ("skip this one", OrderStatus.SUCCEEDED),
        ("wait 60 s", OrderStatus.CANCELLED),
    }
    edits = [r for r in history if is_edit(r)]
    assert edits
    assert all(r.asked is not None and r.asked.via is Via.CLI for r in edits)


# --- spoken: files through `voicectl listen` ---------------------------------------------


def test_every_edit_and_question_spoken(stack: Stack, speech: Speak) -> None:
    """Each edit said by a voice into the robot's own ear, one after the other, and what
    it did to the queue; the queue made ready with typed words between them. (Two of the
    questions: they take the edits' way, and each costs seconds of speech; bench/edits.py
    speaks them all.)"""
    mouth = Mouth(stack, "--awake", "3")

    def spoken(text: str, answer: str | re.Pattern[str]) -> None:
        """Say `text` and wait for `answer` among what the listener says after it (an
        order's read-back may come before an edit's answer: "reach base", then "reach
        base comes after reach bathroom")."""
        answered = mouth.heard("answer: ")
        mouth.say(speech(text, VOICE))

        def since() -> list[str]:
            said = [line.split("answer: ", 1)[1] for line in mouth.lines if "answer: " in line]
            return said[answered:]

        def came() -> bool:
            if isinstance(answer, str):
                return answer in since()
            return any(answer.fullmatch(line) for line in since())

        try:
            wait_until(came, 60.0, f"{answer!r} in answer to {text!r}")
        except AssertionError as exc:
            raise AssertionError(f"{exc}; said: {since()}") from None

    try:
        wait_until(lambda: mouth.heard("listening for commands"), 30.0, "the listener")
        spoken("pause", "paused; 0 waiting")
        say(stack, "reach the kitchen then reach the bathroom then reach base")
        first = state(stack)
        # Two of the questions (every one is typed above, and spoken in bench/edits.py).
        spoken("what are you doing?", "nothing: 3 orders wait until you say go on")
        spoken("where are you?", "at the base")
        spoken("cancel the dumpster", "there is no dumpster in the queue")
        assert queued(state(stack)) == queued(first)
        spoken("cancel the kitchen", "cancelled reach kitchen; 2 left")
        # "undo" typed: Moonshine and Whisper write the word "and do" for Flite's voices,
        # and then nothing is done (bench/edits.py counts it among the refusals)
        assert say(stack, "undo") == ["undone: cancel kitchen"]
        assert queued(state(stack)) == queued(first)
        spoken("do the bathroom first", "reach bathroom is next; 3 left")
        spoken("after that, go to base", "reach base comes after reach bathroom")
        spoken("no, the kitchen", "now reach kitchen, not reach base")
        # two kitchens now: which one is asked, never guessed
        spoken(
            "not the kitchen, the bathroom",
            "2 orders in the queue are kitchen: say which in the panel",
        )
        spoken("no, cancel that", "cancelled reach kitchen; 3 left")
        assert words(state(stack)) == ["reach bathroom", "reach kitchen", "reach base"]
        # in the same breath, the correction replaces the order said: one order queued
        spoken("go to the kitchen, no, the bathroom", "reach bathroom")
        assert words(state(stack)) == [
            "reach bathroom",
            "reach kitchen",
            "reach base",
            "reach bathroom",
        ]
        spoken("clear the queue", "clear the queue. Yes or no?")
        mouth.say(speech("yes", VOICE))
        wait_until(lambda: not state(stack).queue, 30.0, "the queue cleared on a spoken yes")
        assert say(stack, "undo") == ["undone: clear the queue"]
        assert state(stack).queue
        say(stack, "cancel everything")
        say(stack, "wait sixty seconds then wait sixty seconds")
        spoken("go on", "going on; 2 left")
        wait_until(lambda: state(stack).current is not None, 30.0, "the wait to run")
        spoken("skip this one", "skipped wait 60 seconds; next: wait 60 seconds")
        edits = [r for r in state(stack).history if is_edit(r)]
        said = [r for r in edits if r.asked is not None and r.asked.via is Via.VOICE]
        assert len(said) >= 10
        assert all(r.asked is not None and r.asked.spoken for r in said)
        typed = [r for r in edits if r not in said]
        assert typed  # "cancel everything", typed
        assert all(r.asked is not None and r.asked.via is Via.CLI for r in typed)
        # the orders the edits stopped or replaced say which edit did, and were not
        # said twice ("reach base cancelled" after "now reach kitchen, not reach base")
        assert not [line for line in mouth.lines if re.search(r"answer: .* cancelled$", line)]
    finally:
        assert mouth.close() == 0


# --- a supervisor restart ----------------------------------------------------------------


async def test_edits_survive_a_supervisor_restart_and_undo_after_it(
    site: Site, processes: Processes
) -> None:
    """No executor: the orders stay queued, the queue exactly as the edits left it; the
    converter (for the correction) and the supervisor are real, the supervisor killed."""
    processes.start(
        "voicectl.services.converter", "--connect", site.router, "--orders", str(ORDERS)
    )
    site.start_supervisor()
    asked = Asked(via=Via.API, by="test")
    with site.joined() as bus:
        client = VoicectlClient(bus)

        async def send(text: str) -> Sent:
            result = PARSER.parse(text)
            assert not result.errors, result
            return await client.send("r1", result.orders, text, asked)

        async def state() -> State:
            reply = await client.ask("r1", GetState())
            assert isinstance(reply, StateReply)
            return reply.state

        async def up() -> bool:
            try:
                await state()
            except BusError:
                return False
            return True

        await async_wait_until(up, STARTING, "the supervisor")
        await send("reach the kitchen then reach the bathroom then reach base")
        first = await state()

        async def converter_up() -> bool:
            try:
                await client.amend(first.queue[0].order, PARSER.parse("no the base").orders[0])
            except BusError:
                return False
            return True

        await async_wait_until(converter_up, STARTING, "the converter")
        for text in ("cancel the bathroom", "do base first", "after that go to the dumpster"):
            (answered,) = (await send(text)).answers
            assert answered.changed, (text, answered)
        (replaced,) = (await send("no the kitchen")).answers
        assert replaced.answer == "now reach kitchen, not reach dumpster"
        (missing,) = (await send("cancel the dumpster")).answers
        assert not missing.changed
        edited = await state()
        assert words(edited) == ["reach base", "reach kitchen", "reach kitchen"]

        site.kill_supervisor()
        site.start_supervisor()
        await async_wait_until(up, STARTING, "the supervisor again")
        again = await state()
        assert queued(again) == queued(edited)
        assert again.undo == "no, kitchen"
        page = await client.ask("r1", GetHistory(limit=10))
        assert isinstance(page, HistoryPage)
        told = [(r.order.description, r.status, r.message) for r in page.records if is_edit(r)]
        assert told[:2] == [
            ("cancel dumpster", OrderStatus.REJECTED, "there is no dumpster in the queue"),
            ("no, kitchen", OrderStatus.SUCCEEDED, "now reach kitchen, not reach dumpster"),
        ]
        assert all(r.asked == asked for r in page.records if is_edit(r))
        for _ in range(4):
            (undone,) = (await send("undo")).answers
            assert undone.changed, undone
        assert queued(await state()) == queued(first)
        (nothing,) = (await send("undo")).answers
        assert (nothing.answer, nothing.changed) == ("nothing to undo", False)


def is_edit(record: OrderRecord) -> bool:
    return record.order.label == "queue"


def test_the_listener_says_the_answers_aloud(stack: Stack, speech: Speak, tmp_path: Path) -> None:
    """`voicectl listen FILE --speak --speaker ANSWERS.wav`: a question's answer said into
    the WAV file (an edit's answer takes the same way). One utterance a file: the robot's
    ear is deaf while it speaks, so a second command said over its answer is never heard."""
    heard = tmp_path / "answers.wav"
    question = speech("what are you doing?", VOICE)
    done = stack.voicectl(
        *("listen", str(question), "--connect", stack.router, "--awake", "2"),
        *("--speak", "--speaker", str(heard)),
    )
    assert done.returncode == 0, done.stderr
    assert "spoke: nothing: the queue is empty" in done.stderr
    with wave.open(str(heard)) as answers:
        samples = np.frombuffer(answers.readframes(answers.getnframes()), "<i2")
        rate = answers.getframerate()
    assert len(samples) > rate / 2  # a sentence, not a click
    assert np.abs(samples.astype(np.int32)).max() > 1000  # sound, not silence


def test_the_docs_example_of_an_edit_runs_as_written(stack: Stack, tmp_path: Path) -> None:
    """docs/listen.md's example, line by line (its /tmp files in the test's own)."""
    block = block_after(REPO / "docs" / "listen.md", "Try it with a file", "sh")
    done = None
    for command in block.strip().splitlines():
        argv = shlex.split(command.replace("/tmp/", f"{tmp_path}/"))
        if argv[0] == ".venv/bin/voicectl":
            argv = [sys.executable, "-m", "voicectl", *argv[1:], "--connect", stack.router]
        done = subprocess.run(argv, capture_output=True, text=True, cwd=REPO, env=stack.env)
        assert done.returncode == 0, (command, done.stderr)
        if "listen" in argv:
            assert "answer: cancelled reach kitchen; 1 left" in done.stderr
    assert done is not None
    assert "voicectl say: next: reach bathroom" in done.stderr
