"""Noticing that the orders files changed, by polling their metadata.

Polling a few stat() calls every quarter second meets the one-second reload promise
without a dependency or a watcher thread, and it also sees changes that inotify misses
(network and container bind mounts, editors that replace the file by renaming a new one).
"""

from __future__ import annotations

from pathlib import Path

from .orders import orders_files

Signature = tuple[tuple[str, int, int, int], ...]
"""Each orders file with its modification time (ns), size and inode."""


def signature(path: Path) -> Signature:
    """Changes whenever a file is edited, replaced, added or removed."""
    entries = []
    for file in orders_files(path):
        try:
            stat = file.stat()
        except OSError:
            entries.append((str(file), -1, -1, -1))
            continue
        entries.append((str(file), stat.st_mtime_ns, stat.st_size, stat.st_ino))
    return tuple(entries)
