"""How the images install voicectl into their virtualenv (/opt/voicectl), in steps that
the Dockerfile runs in layers of their own, so that a change to the source rebuilds only
the last one:

  python3 install.py deps PYPROJECT [EXTRA,...]   the requirements of the core and the
                                                  extras, from pyproject.toml alone
  python3 install.py wheel SOURCE WHEELS          voicectl's wheel, built from SOURCE
  python3 install.py voicectl WHEELS              voicectl itself; then pip goes (nothing
                                                  installs at run time), with the test
                                                  suites some wheels carry, byte-code
                                                  caches, and the Zenoh extension's
                                                  debugging symbols (33 MB to 23 MB)

Behind a proxy that intercepts TLS, the build secret `ca` is pip's CA bundle: it is
mounted for the steps that download and never becomes a layer."""

import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

SECRET_CA = Path("/run/secrets/ca")


def pip(*args: str) -> None:
    environment = dict(os.environ)
    if SECRET_CA.is_file() and SECRET_CA.stat().st_size:
        environment["PIP_CERT"] = str(SECRET_CA)
    subprocess.run([sys.executable, "-m", "pip", *args], check=True, env=environment)


def requirements(pyproject: Path, extras: list[str]) -> list[str]:
    project = tomllib.loads(pyproject.read_text())["project"]
    optional = project["optional-dependencies"]
    needs = list(project["dependencies"])
    while extras:
        for need in optional[extras.pop()]:
            if need.startswith("voicectl["):  # an extra made of other extras
                extras += need.removeprefix("voicectl[").removesuffix("]").split(",")
            elif need not in needs:
                needs.append(need)
    return needs


def slim() -> None:
    pip("uninstall", "--yes", "--quiet", "pip", "setuptools")
    packages = Path(sysconfig.get_paths()["purelib"])
    for found in sorted(packages.rglob("*"), reverse=True):
        if found.is_dir() and found.name in ("tests", "__pycache__"):
            shutil.rmtree(found)
    for extension in (packages / "zenoh").glob("*.so"):
        subprocess.run(["strip", "--strip-unneeded", str(extension)], check=True)


def main(step: str, *args: str) -> None:
    match step, args:
        case "deps", (pyproject, *extras):
            wanted = [e for part in extras for e in part.split(",") if e]
            pip("install", "--no-compile", *requirements(Path(pyproject), wanted))
        case "wheel", (source, wheels):
            pip("wheel", "--no-deps", "--wheel-dir", wheels, source)
        case "voicectl", (wheels,):
            pip("install", "--no-deps", "--no-compile", *map(str, Path(wheels).glob("*.whl")))
            slim()
        case _:
            raise SystemExit(__doc__)


if __name__ == "__main__":
    main(*sys.argv[1:])
