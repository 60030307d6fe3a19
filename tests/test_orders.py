"""Orders files: the shipped ones load as the issue describes; bad ones fail in one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.converter.orders import OrderSet
from shared.errors import OrdersFileError
from shared.messages import TargetPose

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
    assert [multiply.params(c) for c in multiply.cases] == [{"a": 7, "b": 5}, {"a": 10, "b": 20}]


def test_a_directory_loads_every_file() -> None:
    orders = OrderSet.load(ORDERS)
    assert {o.name for o in orders.orders} >= {"rotation", "goal", "take_photo", "multiply"}


def test_orders_without_wrapper_load() -> None:
    orders = OrderSet.from_yaml("orders:\n  stop: {voice_alias: halt, label: stop}\n")
    assert orders.orders[0].description == "halt"


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
