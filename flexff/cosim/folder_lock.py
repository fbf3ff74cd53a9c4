"""One run at a time in an output folder: a run holds an exclusive lock (fcntl.flock) on a file
in its folder while it writes there, so that a second run into the same folder is refused at
once, naming the first one's process, instead of both clearing and joining each other's record.

The lock file holds the holder's pid, for the message. The kernel drops the lock when the
holder's process ends, however it ends, so a killed run never leaves the folder locked; the
file itself is removed by the run that held it (a run that finds it removed after locking it
locks the new one: two runs never hold two files of one name).
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from flexff.fmu.errors import RunError

LOCK_NAME = ".flexff-run.lock"


class FolderBusy(RunError):
    """Another run is writing into the output folder."""


@contextmanager
def folder_lock(folder: str | Path) -> Iterator[None]:
    """Hold `folder`'s run lock for the block; FolderBusy at once, naming the other run's
    pid, while another process holds it."""
    path = Path(folder) / LOCK_NAME
    fd = _locked(path)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


def _locked(path: Path) -> int:
    """An open descriptor of the lock file at `path`, locked by this process."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise FolderBusy(f"{path.parent}: another flexff run (pid {pid}) is writing into "
                             f"this folder: wait for it to end, or give another output folder "
                             f"(-o)") from None
        try:
            current = os.stat(path).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(fd).st_ino:
            return fd
        os.close(fd)  # its holder removed it as we locked it: lock the new one
