"""The latched emergency stops, in a small file of their own beside the order store.

A STOP latched is also kept in the database, but a database can be emptied, replaced or
damaged; the latch file outlives that, so that a supervisor never starts released after
losing its data. It is read at start and merged with the database (a robot stopped in
either is stopped), and written whenever a STOP is latched or released: in place, padded
to whole blocks, when it is already that large (overwriting needs no free space, so a full
disk does not keep a STOP from being written), else to a new file renamed over it. A file
that cannot be read (a torn write) stops every robot the supervisor serves at start.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import msgspec

BLOCK = 4096
"""The file's size is a whole number of these."""


class LatchRecord(msgspec.Struct, forbid_unknown_fields=True):
    """What the file holds."""

    stopped: list[str]
    """Robots whose emergency stop is latched, sorted."""


@dataclass(frozen=True)
class Latched:
    """What the file said at start."""

    robots: frozenset[str] = frozenset()
    found: bool = False
    """The file was there: the store it stands beside has been used before."""
    unreadable: str = ""
    """Why the file could not be read ('' when it could): then every robot counts as
    stopped."""


class LatchFile:
    def __init__(self, path: Path) -> None:
        self.path = path

    def read(self) -> Latched:
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            return Latched()
        except OSError as exc:
            return Latched(found=True, unreadable=str(exc))
        try:
            record = msgspec.json.decode(raw.strip(), type=LatchRecord)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            return Latched(found=True, unreadable=f"{self.path}: {exc}")
        return Latched(frozenset(record.stopped), found=True)

    def write(self, robots: frozenset[str]) -> None:
        """Write `robots` as the latched ones, durably; OSError if the disk refuses."""
        data = msgspec.json.encode(LatchRecord(stopped=sorted(robots)))
        size = -(-(len(data) + 1) // BLOCK) * BLOCK
        body = data + b" " * (size - len(data) - 1) + b"\n"
        try:
            same_size = self.path.stat().st_size == size
        except FileNotFoundError:
            same_size = False
        if same_size:
            fd = os.open(self.path, os.O_WRONLY)
            try:
                os.pwrite(fd, body, 0)
                os.fsync(fd)
            finally:
                os.close(fd)
            return
        fresh = self.path.with_name(self.path.name + ".new")
        fd = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.write(fd, body)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(fresh, self.path)
        sync_directory(self.path.parent)


def sync_directory(directory: Path) -> None:
    """Make a rename in `directory` durable."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
