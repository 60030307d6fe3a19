"""Orders files: the shipped ones load as the issue describes; bad ones fail in one line."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from voicectl.services.converter.orders import OrderSet, OrdersInvalid
from voicectl.shared.errors import OrdersFileError
from voicectl.shared.messages import TargetPose

ORDERS = Path(__file__).resolve().parents[1] / "orders"


def test_demo_orders_load_with_their_cases() -> None:
    orders = OrderSet.load(ORDERS / "demo.yaml")
    by_name = {o.name: o for o in orders.orders}
    assert set(by_name) == {"rotation", "goal", "local_goal"}
    assert orders.separator == "then"
    rotation = by_name["rotation"]
    assert [c.name for c in rotation.cases] == ["left", "right", "back"]
    back = rotation.cases[2]
    assert rotation.full_description(back) == "turn back"
    assert rotation.target_pose(back) == TargetPose(frame="base_link", yaw=3.14)
    kitchen = next(c for c in by_name["goal"].cases if c.name == "kitchen")
    assert by_name["goal"].target_pose(kitchen) == TargetPose(frame="map", x=3, y=5, yaw=1.0)
    assert by_name["goal"].params(kitchen) == {}


def test_tutorial_orders_keep_extra_keys_as_params() -> None:
    orders = OrderSet.load(ORDERS / "tutorial.yaml")
    by_name = {o.name: o for o in orders.orders}
    photo = by_name["take_photo"]
    assert photo.label == "pic"
    assert photo.params(None) == {"wait": 5}
    assert photo.target_pose(None) is None
    multiply = by_name["multiply"]
    assert [multiply.params(c) for c in multiply.cases] == [
        {"first": 7, "second": 5},
        {"first": 10, "second": 20},
    ]


def test_a_directory_loads_every_file() -> None:
    orders = OrderSet.load(ORDERS)
    assert {o.name for o in orders.orders} >= {"rotation", "goal", "take_photo", "multiply"}


def test_orders_without_wrapper_load() -> None:
    orders = OrderSet.from_yaml("orders:\n  stop: {voice_alias: halt, label: stop}\n")
    assert orders.orders[0].description == "halt"


def test_an_alias_that_is_a_regex_is_not_what_a_person_reads() -> None:
    """Without a description, an order or case reads as its alias when that is words, and
    as its name when the alias is a regex ('wait|pause' is shown as 'pause')."""
    orders = OrderSet.from_yaml(
        "orders:\n"
        "  pause: {voice_alias: 'wait|pause', label: wait}\n"
        "  ahead: {voice_alias: 'ahead {d} m', label: drive, slots: {d: {min: 1, max: 3}}}\n"
        "  take_photo:\n"
        "    voice_alias: '(take|snap)'\n"
        "    label: pic\n"
        "    cases: {a_picture: {voice_alias: '(a )?(picture|photo)'}}\n"
    )
    pause, ahead, photo = orders.orders
    assert (pause.description, ahead.description) == ("pause", "ahead {d} m")
    assert photo.full_description(photo.cases[0]) == "take photo a picture"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "orders:\n  spin: {label: mbgoal}\n",
            "f.yaml: order 'spin': missing mandatory key 'voice_alias'",
        ),
        (
            "orders:\n  spin: {voice_alias: spin}\n",
            "f.yaml: order 'spin': missing mandatory key 'label'",
        ),
        (
            "orders:\n  spin:\n    voice_alias: spin\n    label: x\n"
            "    cases:\n      fast: {speed: 2}\n",
            "f.yaml: order 'spin' case 'fast': missing mandatory key 'voice_alias'",
        ),
        ("orders:\n  spin: {voice_alias: 'sp(in', label: x}\n", "invalid regex 'sp(in'"),
        ("orders:\n  spin: {voice_alias: 'a?', label: x}\n", "matches empty text"),
        ("orders: [1, 2]\n", "f.yaml: expected a mapping with an 'orders' mapping"),
        ("orders:\n  spin: {voice_alias: spin, label: x\n", "f.yaml:3: invalid YAML"),
        (
            "orders:\n  go: {voice_alias: go, label: x, frame: map, x: far}\n",
            "f.yaml: order 'go': 'x' must be a number, got 'far'",
        ),
        (
            "orders:\n  go: {voice_alias: go, label: x, speeds: [1, 2]}\n",
            "parameter 'speeds' must be a string, number or boolean",
        ),
        ("orderz: {}\n", "expected a mapping with an 'orders' mapping"),
        (
            "orders:\n  go: {voice_alias: go, label: x, frame: map, x: .nan}\n",
            "f.yaml: order 'go': parameter 'x' must be a finite number, got nan",
        ),
        (
            "orders:\n  go:\n    voice_alias: go\n    label: x\n    cases:\n"
            "      far: {voice_alias: far, frame: map, yaw: -.inf}\n",
            "f.yaml: order 'go' case 'far': parameter 'yaw' must be a finite number, got -inf",
        ),
        (
            "orders:\n  go: {voice_alias: go, label: drive, distance: .inf}\n",
            "f.yaml: order 'go': parameter 'distance' must be a finite number, got inf",
        ),
    ],
)
def test_bad_orders_fail_in_one_line_naming_file_order_and_key(text: str, message: str) -> None:
    with pytest.raises(OrdersFileError) as caught:
        OrderSet.from_yaml(text, "f.yaml")
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_duplicate_order_names_across_files_name_both(tmp_path: Path) -> None:
    (tmp_path / "a.yaml").write_text("orders:\n  go: {voice_alias: go, label: x}\n")
    (tmp_path / "b.yaml").write_text("orders:\n  go: {voice_alias: walk, label: x}\n")
    with pytest.raises(OrdersFileError, match=r"b.yaml: order 'go' is already defined in .*a.yaml"):
        OrderSet.load(tmp_path)


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(OrdersFileError, match="cannot read orders file"):
        OrderSet.load(tmp_path / "nope.yaml")


# --- slots, line numbers, several errors ----------------------------------------------------


def test_spoken_orders_load_with_their_slots() -> None:
    orders = OrderSet.load(ORDERS / "spoken.yaml")
    by_name = {o.name: o for o in orders.orders}
    assert set(by_name) == {"turn_by", "drive", "wait"}
    angle = by_name["turn_by"].slots["angle"]
    assert (angle.unit.name, angle.min, angle.max, angle.to) == ("deg", 1, 180, "yaw")
    right = next(c for c in by_name["turn_by"].cases if c.name == "right")
    assert right.slots["angle"].sign == -1
    assert [c.name for c in orders.commands] == [
        "turn_by/left",
        "turn_by/right",
        "drive/forward",
        "drive/back",
        "wait",
    ]
    assert [c.name for c in orders.prefixes] == ["turn_by", "drive"]


def test_every_shipped_file_loads_together() -> None:
    orders = OrderSet.load(ORDERS)
    assert {"rotation", "turn_by", "wait", "take_photo"} <= {o.name for o in orders.orders}


SLOTTED = """\
orders:
  go:
    voice_alias: "go"
    label: x
    frame: base_link
    cases:
      ahead:
        voice_alias: "ahead {distance} meters"
        slots:
          distance: {unit: m, min: 0.1, max: 5, to: x}
"""


@pytest.mark.parametrize(
    ("broken", "message"),
    [
        (
            SLOTTED.replace("min: 0.1, max: 5, ", ""),
            "f.yaml: order 'go' case 'ahead': slot 'distance': 'min' and 'max' are mandatory "
            "(in m) (line 10)",
        ),
        (
            SLOTTED.replace("{distance}", "{range}"),
            "f.yaml: order 'go' case 'ahead': slot '{range}' is not declared; declared: "
            "distance (line 8)",
        ),
        (
            SLOTTED.replace("{distance} meters", "{distance} {distance}"),
            "slot '{distance}' appears twice in one command",
        ),
        (
            SLOTTED.replace("{distance} meters", "meters"),
            "f.yaml: order 'go' case 'ahead': slot(s) distance declared but not in any alias",
        ),
        (
            SLOTTED.replace("to: x", "to: yaw"),
            "'yaw' needs a unit of angle, got m (length); allowed: deg, rad (line 10)",
        ),
        (
            SLOTTED.replace('"ahead {distance} meters"', '"ahead {distance} meter\'s"'),
            "alias can never match 'meter's': text is matched without punctuation "
            "(write 'meter s')",
        ),
        (
            SLOTTED.replace('"ahead {distance} meters"', '"ahead ({distance} meters"'),
            "f.yaml: order 'go' case 'ahead': 'voice_alias': invalid regex "
            "'ahead ({distance} meters': missing ), unterminated subpattern at position 6 "
            "(line 8)",
        ),
        (
            SLOTTED.replace("          distance:", "          distance: 5\n          old:"),
            "slot 'distance': expected a mapping, got int (line 10)",
        ),
        (
            SLOTTED.replace("    cases:", "    speeds: [1, 2]\n    cases:"),
            "f.yaml: order 'go': parameter 'speeds' must be a string, number or boolean, "
            "got list (line 6)",
        ),
        (
            SLOTTED.replace('voice_alias: "ahead {distance} meters"', "description: ahead"),
            "f.yaml: order 'go' case 'ahead': missing mandatory key 'voice_alias' (line 8)",
        ),
    ],
)
def test_bad_slots_fail_in_one_line_with_file_order_case_and_line(
    broken: str, message: str
) -> None:
    with pytest.raises(OrdersInvalid) as caught:
        OrderSet.from_yaml(broken, "f.yaml")
    (error,) = caught.value.errors
    assert message in error
    assert "\n" not in error
    # The exception's own text, which the CLI prints, is the same without the line.
    assert str(caught.value) == re.sub(r" \(line \d+\)$", "", error)


def test_a_valid_slot_file_loads() -> None:
    command = OrderSet.from_yaml(SLOTTED, "f.yaml").commands[0]
    assert command.name == "go/ahead"
    assert list(command.slots) == ["distance"]
    assert command.expansion.finite


def test_every_bad_order_is_reported_not_only_the_first() -> None:
    text = (
        "orders:\n"
        "  spin: {label: mbgoal}\n"
        "  good: {voice_alias: good, label: x}\n"
        "  jump: {voice_alias: 'ju(mp', label: x}\n"
    )
    with pytest.raises(OrdersInvalid) as caught:
        OrderSet.from_yaml(text, "f.yaml")
    assert caught.value.errors == (
        "f.yaml: order 'spin': missing mandatory key 'voice_alias' (line 2)",
        "f.yaml: order 'jump': 'voice_alias': invalid regex 'ju(mp': missing ), unterminated "
        "subpattern at position 2 (line 4)",
    )
    assert str(caught.value) == (
        "f.yaml: order 'spin': missing mandatory key 'voice_alias' (and 1 more)"
    )


def test_errors_in_several_files_of_a_directory_are_all_reported(tmp_path: Path) -> None:
    (tmp_path / "a.yaml").write_text("orders:\n  go: {voice_alias: go}\n")
    (tmp_path / "b.yaml").write_text("orders:\n  stop: {voice_alias: '(', label: x}\n")
    (tmp_path / "c.yaml").write_text("orders:\n  fine: {voice_alias: fine, label: x}\n")
    with pytest.raises(OrdersInvalid) as caught:
        OrderSet.load(tmp_path)
    assert [e.split(":")[0] for e in caught.value.errors] == [
        str(tmp_path / "a.yaml"),
        str(tmp_path / "b.yaml"),
    ]


def test_duplicate_names_give_the_line_of_the_second(tmp_path: Path) -> None:
    (tmp_path / "a.yaml").write_text("orders:\n  go: {voice_alias: go, label: x}\n")
    (tmp_path / "b.yaml").write_text(
        "orders:\n  stop: {voice_alias: stop, label: x}\n  go: {voice_alias: walk, label: x}\n"
    )
    with pytest.raises(OrdersInvalid) as caught:
        OrderSet.load(tmp_path)
    assert caught.value.errors == (
        f"{tmp_path / 'b.yaml'}: order 'go' is already defined in {tmp_path / 'a.yaml'} (line 3)",
    )


@pytest.mark.parametrize(
    "text",
    [
        "",
        "\x00\x01\x02",
        "orders:\n  go: {voice_alias: go, label: x}\n  " + "x" * 100_000,
        "orders: !!python/object:os.system {}\n",
        "orders:\n  ? [1, 2]\n  : {voice_alias: go, label: x}\n",
    ],
)
def test_junk_files_are_one_line_errors(text: str) -> None:
    with pytest.raises(OrdersFileError) as caught:
        OrderSet.from_yaml(text, "f.yaml")
    assert "\n" not in str(caught.value)
    assert str(caught.value).startswith("f.yaml")


def test_every_parse_example_in_the_orders_doc_gives_what_it_shows() -> None:
    doc = (ORDERS.parent / "docs" / "orders.md").read_text()
    examples = re.findall(
        r"```sh\n\.venv/bin/voicectl parse ([^\n]*)\n```\n\n(?:[^`]*\n)?```json\n(.*?)```",
        doc,
        re.DOTALL,
    )
    assert len(examples) >= 4
    for arguments, shown in examples:
        done = subprocess.run(
            [sys.executable, "-m", "voicectl", "parse", *shlex.split(arguments)],
            capture_output=True,
            text=True,
            check=False,
            cwd=ORDERS.parent,
        )
        expected = json.loads(shown)
        assert json.loads(done.stdout) == expected, arguments
        assert done.returncode == (1 if expected["errors"] else 0), arguments
