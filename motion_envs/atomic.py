"""Atomic file writes: write a temporary file beside the target, then rename it into place.

Temporary files are named `.NAME.PID.RANDOM.tmpSUFFIX` (PID: the writing process). A
process killed mid-write (SIGKILL runs no cleanup) leaves its temporary file
behind; the next write of the same target removes those whose process is gone.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def remove_orphans(path: str | Path) -> list[Path]:
    """Delete the temporary files of earlier writes of `path` whose writing process has ended; returns them."""
    path = Path(path)
    removed = []
    for candidate in path.parent.glob(f".{path.name}.*.tmp*"):
        pid = candidate.name[len(path.name) + 2 :].split(".", 1)[0]
        if not pid.isdigit() or not _alive(int(pid)):  # no pid: an older version's temporary file
            candidate.unlink(missing_ok=True)
            removed.append(candidate)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside `path` (same suffix, so writers that go by the extension work) that becomes `path`
    (mode 0644) when the block ends without an error; on an error it is removed and `path` is left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_orphans(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=f".tmp{path.suffix}")
    os.close(handle)
    try:
        yield Path(temporary)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)


def atomic_write(path: str | Path, write: Callable[[BinaryIO], None]) -> Path:
    """Call `write(file)` on a temporary file beside `path` and rename it to `path` (mode 0644).

    A reader sees the old file or the whole new one, never half of it; a
    failed write leaves no temporary file behind.
    """
    with atomic_path(path) as temporary, open(temporary, "wb") as file:
        write(file)
    return Path(path)
