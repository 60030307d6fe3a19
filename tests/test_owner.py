"""Whom the executor takes orders from (services/executor/owner.py): `sender` walked over
who holds the robot's owner token and who answers as its supervisor, against the rule the
supervisors keep (shared/ownership.py)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.executor.owner import Refuse, Take, sender
from voicectl.shared.messages import Execute, Order, OrderRecord, OrderStatus, State

ROBOT = "r1"
GO = Order(order="go", label="drive", description="go", params={"distance": 1.0})
OTHER = Order(order="go", label="drive", description="go", params={"distance": 9.0})
ZIDS = st.sampled_from(["a1", "b2", "c3"])


def runs(order_id: str | None, order: Order = GO) -> State:
    """A supervisor's state that runs `order_id` (None: nothing)."""
    current = None
    if order_id is not None:
        current = OrderRecord(id=order_id, order=order, status=OrderStatus.RUNNING)
    return State(robot=ROBOT, current=current)


ANSWER = st.one_of(
    st.builds(runs, st.none()),
    st.builds(runs, st.sampled_from(["x", "y"])),
    st.builds(runs, st.just("x"), st.just(OTHER)),
)
"""What a process answering as the supervisor may say it runs: nothing, order x, order y,
or an order x that is not the one offered."""


@given(st.lists(ZIDS, max_size=3), st.dictionaries(ZIDS, ANSWER, max_size=3))
def test_an_order_is_taken_only_from_the_one_supervisor_that_runs_it(
    tokens: list[str], answers: dict[str, State]
) -> None:
    """Taken exactly when one process both holds a token and answers as the supervisor,
    and what it runs is this order, same id and same content; refused otherwise, in one
    line that names the robot."""
    execute = Execute(order_id="x", order=GO)
    verdict = sender(ROBOT, execute, tokens, answers)
    supervising = sorted({tag for tag in tokens if tag in answers})
    if len(supervising) == 1:
        current = answers[supervising[0]].current
        if current is not None and (current.id, current.order) == ("x", GO):
            assert verdict == Take(supervising[0])
            return
    assert isinstance(verdict, Refuse)
    assert f"robot '{ROBOT}'" in verdict.reason
    assert "\n" not in verdict.reason
    for zid in supervising if len(supervising) > 1 else ():
        assert zid in verdict.reason


def test_each_refusal_says_why() -> None:
    execute = Execute(order_id="x", order=GO)
    assert sender(ROBOT, execute, [], {}) == Refuse(
        "no supervisor owns robot 'r1' (no owner token is up): orders for robot 'r1' are "
        "taken from its supervisor only"
    )
    made_up = sender(ROBOT, execute, ["z9"], {})
    assert isinstance(made_up, Refuse)
    assert "Zenoh id z9, which does not answer as its supervisor" in made_up.reason
    no_token = sender(ROBOT, execute, [], {"a1": runs("x")})
    assert isinstance(no_token, Refuse)
    assert "no owner token is up" in no_token.reason
    not_this = sender(ROBOT, execute, ["a1"], {"a1": runs("y")})
    assert isinstance(not_this, Refuse)
    assert "order 'x' is not the one robot 'r1''s supervisor (Zenoh id a1) runs" in not_this.reason
    two = sender(ROBOT, execute, ["a1", "b2"], {"a1": runs("x"), "b2": runs("x")})
    assert isinstance(two, Refuse)
    assert "2 processes claim robot 'r1'" in two.reason
