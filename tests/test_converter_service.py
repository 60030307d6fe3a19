"""The converter as a process on a real Zenoh router: queries, late starters, proposals, and
hot reload of its orders files (a good edit applies within a second, a bad one keeps the
previous orders and says why)."""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from harness.wait import async_wait_until, wait_until
from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.messages import (
    ConverterReply,
    Failed,
    GetGrammar,
    Grammar,
    OrdersStatus,
    ParseReply,
    ParseRequest,
    ParseResult,
    Proposal,
    Transcript,
)

from .conftest import Processes
from .support import joined, until_heard

ORDERS = Path(__file__).resolve().parents[1] / "orders"
KEYS = ConverterKeys()
WAIT = 30.0
"""Generous: the machine is shared; every wait ends as soon as the data is there."""

WAVE = """\
    wave:
      voice_alias: "wave( hello)?"
      label: "wave"
"""


class Converter:
    """One converter process and the test's own subscriptions to what it publishes."""

    def __init__(self, bus: Bus, processes: Processes, router: str, orders: Path) -> None:
        self.bus = bus
        self.statuses: list[OrdersStatus] = []
        self.grammars: list[Grammar] = []
        self.alive: list[bool] = []
        bus.subscribe(KEYS.status, json_decoder(OrdersStatus), lambda _k, m: self._got(m))
        bus.subscribe(KEYS.grammars, json_decoder(Grammar), lambda _k, m: self.grammars.append(m))
        bus.watch(KEYS.alive(), lambda _k, alive: self.alive.append(alive))
        self.process = processes.start(
            "voicectl.services.converter", "--connect", router, "--orders", str(orders), "--debug"
        )
        self.status_times: list[float] = []

    def _got(self, status: OrdersStatus) -> None:
        self.statuses.append(status)
        self.status_times.append(time.monotonic())

    async def started(self) -> None:
        def seen() -> str:
            return (
                f"token {self.alive}, {len(self.statuses)} status(es), "
                f"{len(self.grammars)} grammar(s)"
            )

        try:
            await async_wait_until(
                lambda: self.alive and self.statuses and self.grammars, WAIT, "the converter"
            )
        except AssertionError as exc:
            raise AssertionError(f"{exc}; seen: {seen()}") from exc

    async def status(
        self, seen: int, where: Callable[[OrdersStatus], bool]
    ) -> tuple[OrdersStatus, float]:
        """The first status after the `seen` first ones for which `where` holds, and when it
        arrived. (The converter sends its last status again when a subscriber appears, so
        a status can come twice.)"""

        def found() -> int | None:
            for index in range(seen, len(self.statuses)):
                if where(self.statuses[index]):
                    return index
            return None

        await async_wait_until(lambda: found() is not None, WAIT, "a status")
        index = found()
        assert index is not None
        return self.statuses[index], self.status_times[index]

    async def grammar(self, where: Callable[[Grammar], bool]) -> Grammar:
        await async_wait_until(lambda: any(map(where, self.grammars)), WAIT, "a grammar")
        return next(g for g in self.grammars if where(g))

    async def ask(self, text: str) -> ParseResult:
        reply = await self.bus.request(
            KEYS.parse, ParseRequest(text=text), json_decoder(ConverterReply), timeout=10.0
        )
        assert isinstance(reply, ParseReply), reply
        return reply.result


@contextlib.asynccontextmanager
async def scenario(router: str, processes: Processes, orders: Path) -> AsyncIterator[Converter]:
    """A converter serving `orders`, started, and the test's side of it."""
    with joined(router) as bus:
        converter = Converter(bus, processes, router, orders)
        await converter.started()
        yield converter


def write(path: Path, text: str) -> None:
    """Replace the file the way editors do: a new file renamed over the old one."""
    temporary = path.with_suffix(".tmp")
    temporary.write_text(text)
    os.replace(temporary, path)


async def test_queries_answer_a_recogniser_that_starts_late(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    orders = tmp_path / "orders"
    shutil.copytree(ORDERS, orders)

    async with scenario(router, processes, orders) as converter:
        status = converter.statuses[0]
        assert status.ok
        assert status.errors == []
        assert status.orders == 8 + 18  # and orders/queue.yaml's edits and questions
        assert len(status.sources) == 10  # the orders in English, Spanish and German
        assert status.languages == ["de", "en", "es"]
        await async_wait_until(
            lambda: {g.language for g in converter.grammars} == {"de", "en", "es"},
            WAIT,
            "a grammar per language at start",
        )
        with joined(router) as late:
            grammar = await late.request(
                KEYS.parse, GetGrammar(), json_decoder(ConverterReply), timeout=10.0
            )
            assert isinstance(grammar, Grammar)
            assert grammar == next(g for g in converter.grammars if g.language == "en")
            assert "go forward two point five meters" in grammar.phrases
            assert "#JSGF" in grammar.jsgf
            spanish = await late.request(
                KEYS.parse, GetGrammar(language="es"), json_decoder(ConverterReply), timeout=10.0
            )
            assert isinstance(spanish, Grammar)
            assert spanish.language == "es"
            assert "espera diez segundos" in spanish.phrases
            assert "treinta" in spanish.words
            unknown = await late.request(
                KEYS.parse, GetGrammar(language="fr"), json_decoder(ConverterReply), timeout=10.0
            )
            assert isinstance(unknown, Failed)
            assert unknown.reason == "no orders in language 'fr'; languages: de, en, es"
        result = await converter.ask("go forward two point five meters then dance")
        assert [(o.order, o.case) for o in result.orders] == [("drive", "forward")]
        assert result.orders[0].target_pose is not None
        assert result.orders[0].target_pose.x == 2.5
        assert [e.text for e in result.errors] == ["dance"]
        junk = await converter.bus.request_bytes(KEYS.parse, b"\xff\x00junk", 10.0)
        assert b"undecodable request" in junk


async def test_final_transcripts_become_proposals_per_robot(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    async with scenario(router, processes, ORDERS / "demo.yaml") as converter:
        proposals: list[Proposal] = []
        robot = RobotKeys("r1")
        converter.bus.subscribe(
            robot.proposal, json_decoder(Proposal), lambda _k, p: proposals.append(p)
        )
        await until_heard(converter.bus, robot.transcript)
        converter.bus.publish(robot.transcript, Transcript(text="turn left then reach base"))
        await async_wait_until(lambda: proposals, WAIT, "a proposal")
        proposal = proposals[0]
        assert proposal.transcript == "turn left then reach base"
        assert [o.case for o in proposal.orders] == ["left", "base"]
        assert not proposal.rejected
        assert proposal.errors == []
        # Speech that makes only part of an order list is not half-obeyed: a part that did
        # not parse says the rest may be misheard too.
        heard = len(proposals)
        converter.bus.publish(robot.transcript, Transcript(text="turn lift then reach base"))
        await async_wait_until(lambda: len(proposals) > heard, WAIT, "the second proposal")
        partial = proposals[-1]
        assert partial.rejected
        assert partial.orders == []
        assert "not a command" in partial.errors[0].reason
        assert "'turn lift'" in partial.errors[0].reason
        assert partial.errors[0].candidates == ["turn left"]


async def test_a_valid_edit_applies_within_a_second(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    orders = tmp_path / "orders.yaml"
    shutil.copy(ORDERS / "demo.yaml", orders)

    async with scenario(router, processes, orders) as converter:
        await async_wait_until(lambda: converter.grammars, WAIT, "the grammar at start")
        assert (await converter.ask("wave")).orders == []
        seen = len(converter.statuses)
        write(orders, orders.read_text() + WAVE)
        edited = time.monotonic()
        status, arrived = await converter.status(seen, lambda s: s.orders == 4)
        assert status.ok, status
        assert arrived - edited < 1.0
        grammar = await converter.grammar(lambda g: "wave hello" in g.phrases)
        assert grammar.version != converter.grammars[0].version
        (wave,) = (await converter.ask("please wave hello")).orders
        assert wave.label == "wave"

        # An edit in place, not by renaming, is seen too.
        orders.write_text(orders.read_text().replace("wave( hello)?", "wave( goodbye)?"))
        await converter.grammar(lambda g: "wave goodbye" in g.phrases)
        assert (await converter.ask("wave goodbye")).errors == []


async def test_an_invalid_edit_keeps_the_previous_orders_and_says_why(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    orders = tmp_path / "orders.yaml"
    shutil.copy(ORDERS / "spoken.yaml", orders)
    good = orders.read_text()

    async with scenario(router, processes, orders) as converter:
        await async_wait_until(lambda: converter.grammars, WAIT, "the grammar at start")
        seen = len(converter.statuses)
        broken = good.replace("wait {duration}", "wait ({duration}").replace(
            "(forward|ahead) {distance}", "(forward|ahead) {distanse}"
        )
        write(orders, broken)
        status, _ = await converter.status(seen, lambda s: not s.ok)
        assert status.orders == 3  # the previous ones, still running
        assert status.errors == [
            f"{orders}: order 'drive' case 'forward': slot '{{distanse}}' is not declared; "
            "declared: distance (line 34)",
            f"{orders}: order 'wait': 'voice_alias': invalid regex 'wait ({{duration}} "
            "seconds?': missing ), unterminated subpattern at position 5 (line 42)",
        ]
        (wait,) = (await converter.ask("wait ten seconds")).orders
        assert wait.params == {"seconds": 10.0}
        grammar = await converter.bus.request(
            KEYS.parse, GetGrammar(), json_decoder(ConverterReply), timeout=10.0
        )
        assert grammar == converter.grammars[0]
        # No grammar for orders that did not load (the first may have come twice).
        assert {g.version for g in converter.grammars} == {grammar.version}

        seen = len(converter.statuses)
        write(orders, good.replace("min: 0.5, max: 60", "max: 60"))
        status, _ = await converter.status(seen, lambda s: "mandatory" in str(s.errors))
        assert status.errors == [
            f"{orders}: order 'wait': slot 'duration': 'min' and 'max' are mandatory (in s) "
            "(line 46)"
        ]

        seen = len(converter.statuses)
        write(orders, good.replace("max: 60", "max: 120"))
        await converter.status(seen, lambda s: s.ok)
        assert (await converter.ask("wait ninety seconds")).errors == []


async def test_a_directory_reports_duplicate_names_and_reloads_when_files_come_and_go(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    directory = tmp_path / "orders"
    directory.mkdir()
    shutil.copy(ORDERS / "demo.yaml", directory / "a.yaml")

    async with scenario(router, processes, directory) as converter:
        seen = len(converter.statuses)
        (directory / "b.yaml").write_text(
            "orders:\n  stop: {voice_alias: stop, label: x}\n  goal: {voice_alias: go, label: x}\n"
        )
        status, _ = await converter.status(seen, lambda s: not s.ok)
        assert status.errors == [
            f"{directory / 'b.yaml'}: order 'goal' is already defined in "
            f"{directory / 'a.yaml'} (line 3)"
        ]
        seen = len(converter.statuses)
        write(directory / "b.yaml", "orders:\n  stop: {voice_alias: stop, label: x}\n")
        await converter.status(seen, lambda s: s.ok and s.orders == 4)
        assert (await converter.ask("stop")).orders[0].order == "stop"
        seen = len(converter.statuses)
        (directory / "b.yaml").unlink()
        await converter.status(seen, lambda s: s.ok and s.orders == 3)
        assert (await converter.ask("stop")).errors[0].reason == "no order matches"


def test_a_bad_file_at_start_is_fatal_in_one_line(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    orders = tmp_path / "bad.yaml"
    orders.write_text("orders:\n  go:\n    voice_alias: 'go {d}'\n    label: x\n")
    process = processes.start(
        "voicectl.services.converter", "--connect", router, "--orders", str(orders)
    )
    wait_until(lambda: process.poll() is not None, WAIT, "the converter to refuse the file")
    assert process.returncode == 2
    *logged, last = processes.log(process).strip().splitlines()
    assert last == (
        f"voicectl converter: {orders}: order 'go': slot '{{d}}' is not declared; declared: none"
    )
    assert logged[-1].endswith(
        f"ERROR __main__: {orders}: order 'go': slot '{{d}}' is not "
        "declared; declared: none (line 3)"
    )


async def test_no_converter_means_no_answer(router: str) -> None:
    with joined(router) as bus, pytest.raises(BusError):
        await bus.request(KEYS.parse, GetGrammar(), json_decoder(ConverterReply), 1.0)
