"""Executor bindings from the command line and from executors files: what loads, and the
one-line error for what does not."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness.executors import Greeter, Strict
from voicectl.services.executor.framework import BindingError, load_bindings_file, order_params
from voicectl.shared.messages import Order

from .conftest import voicectl


def bindings_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "executors.yaml"
    path.write_text(text)
    return path


def test_a_file_binds_one_class_twice_with_its_own_arguments(tmp_path: Path) -> None:
    path = bindings_file(
        tmp_path,
        "executors:\n"
        "  - class: harness.executors:Greeter\n"
        "    args: {greeting: hi}\n"
        "  - {class: harness.executors:Greeter, labels: [bye, ciao], "
        "args: {greeting: bye, times: 3}}\n",
    )
    (first, first_labels), (second, second_labels) = load_bindings_file(path)
    assert isinstance(first, Greeter)
    assert isinstance(second, Greeter)
    assert (first.greeting, first.times, first_labels) == ("hi", 1, ("greet",))
    assert (second.greeting, second.times, second_labels) == ("bye", 3, ("bye", "ciao"))


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("executors: [}", "executors.yaml: "),
        ("executor: []", "executors.yaml: Object contains unknown field `executor`"),
        (
            "executors:\n  - {class: harness.executors:Greeter, label: [x]}",
            "executors.yaml: Object contains unknown field `label` - at `$.executors[0]`",
        ),
        (
            "executors:\n  - {class: no_such_module:Thing}",
            "executors.yaml: executors entry 1: executor 'no_such_module:Thing': cannot import "
            "no_such_module: No module named 'no_such_module'",
        ),
        (
            "executors:\n  - {class: harness.executors:Greeter, args: {tone: warm}}",
            "executors.yaml: executors entry 1: executor 'harness.executors:Greeter': "
            "Greeter() failed: Greeter.__init__() got an unexpected keyword argument 'tone'",
        ),
        (
            "executors:\n  - {class: harness.executors:Speed}",
            "executors.yaml: executors entry 1: executor 'harness.executors:Speed': "
            "Speed is not an Executor class",
        ),
    ],
)
def test_a_bad_file_is_one_line_naming_file_and_entry(
    tmp_path: Path, text: str, error: str
) -> None:
    with pytest.raises(BindingError) as refused:
        load_bindings_file(bindings_file(tmp_path, text))
    message = str(refused.value)
    assert "\n" not in message
    assert message.startswith(f"{tmp_path}/{error}")


def test_a_missing_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(BindingError, match=r"nowhere\.yaml: No such file or directory"):
        load_bindings_file(tmp_path / "nowhere.yaml")


def test_the_executor_refuses_to_start_with_a_bad_file(tmp_path: Path) -> None:
    path = bindings_file(tmp_path, "executors:\n  - {class: no_such_module:Thing}")
    done = voicectl("executor", "--executors", str(path), timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].startswith(f"voicectl executor: {path}: ")


def test_typed_parameters_are_converted_once() -> None:
    order = Order(order="go", label="strict", description="go", params={"metres_per_second": 1})
    speed = order_params(Strict(), order)
    assert (speed.metres_per_second, speed.mode) == (1.0, "cruise")
    untyped = Order(order="greet", label="greet", description="greet", params={"x": 1})
    assert order_params(Greeter("hi"), untyped) == {"x": 1}
