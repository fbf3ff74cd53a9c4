"""Ctrl-C and SIGTERM end a run even while an FMU hangs in a call: Python runs a signal's handler
only between its own instructions, so a run stuck in an in-process FMU's code (or in an
isolated FMU's call without a step timeout) would never see it.

While the steps run, Python's own signal handler also writes the signal's number to a pipe
(signal.set_wakeup_fd), from C, whatever the main thread does; a thread reads it. Where the run
has not ended GRACE_S seconds after an interrupt, the thread removes the run's temporary
folders, says on one line what the record kept (its chunks up to the last one, which are
complete files), and ends the process with the interrupt's exit code. A run that answers the
interrupt in time ends as any other does (cosim.run).
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

GRACE_S = 5.0  # seconds a run has to answer an interrupt itself
EXITS = {signal.SIGINT: ("interrupted", 130), signal.SIGTERM: ("terminated", 143)}


@contextmanager
def watchdog(kept: str, scratch: Callable[[], Sequence[Path]]) -> Iterator[None]:
    """Watch for Ctrl-C and SIGTERM during the block (module doc); `kept` says where the
    record's chunks are, `scratch()` lists the temporary folders to remove. Outside the main
    thread (which alone receives signals) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    read, write = os.pipe()
    os.set_blocking(write, False)
    previous = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    done = threading.Event()
    thread = threading.Thread(target=_watch, args=(read, done, kept, scratch), daemon=True,
                              name="flexff-watchdog")
    thread.start()
    try:
        yield
    finally:
        done.set()
        signal.set_wakeup_fd(previous)
        os.close(write)  # the thread reads the end of the pipe and returns
        thread.join()
        os.close(read)


def _watch(read: int, done: threading.Event, kept: str,
           scratch: Callable[[], Sequence[Path]]) -> None:
    """The watchdog's thread: wait for an interrupt, give the run GRACE_S to answer it."""
    while True:
        data = os.read(read, 1)
        if not data or done.is_set():
            return
        number = signal.Signals(data[0]) if data[0] in EXITS else None
        if number is None or done.wait(GRACE_S):
            continue
        for folder in scratch():
            shutil.rmtree(folder, ignore_errors=True)
        word, code = EXITS[number]
        print(f"flexff: {word}; an FMU did not return from its call within {GRACE_S:g} s, so "
              f"the run was ended there: {kept}", file=sys.stderr, flush=True)
        os._exit(code)
