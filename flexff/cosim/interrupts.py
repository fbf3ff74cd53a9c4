"""Ctrl-C and SIGTERM held back while the engine steps, and raised where the run can keep what
it made. Python runs a signal's handler in whatever Python code runs next, which during a run is
often an FMU's logger callback: the exception cannot cross the C frames of the engine, ctypes
prints and drops it, and the run goes on as if never interrupted. Inside `deferred`, the
handlers only note the signal; the master raises it at its safe points (between the engine's
calls), where it first hands over the points recorded so far. A run stuck in an FMU's call
never reaches one: cosim.watchdog ends it."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def deferred() -> Iterator[Callable[[], None]]:
    """Note SIGINT and SIGTERM during the block instead of handling them; the function yielded
    raises the first noted one by its own handler (KeyboardInterrupt, fmu.errors.Terminated),
    as does leaving the block with one noted. Handlers that are not Python functions
    (SIG_DFL, SIG_IGN), and any outside the main thread, are left as they are."""
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    noted: list[tuple[int, FrameType | None]] = []
    previous: dict[int, Callable[[int, FrameType | None], Any]] = {}

    def note(number: int, frame: FrameType | None) -> None:
        noted.append((number, frame))

    def raise_noted() -> None:
        if noted:
            number, frame = noted[0]
            noted.clear()
            previous[number](number, frame)

    for caught in SIGNALS:
        handler = signal.getsignal(caught)
        if callable(handler):
            previous[caught] = handler
            signal.signal(caught, note)
    try:
        yield raise_noted
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        raise_noted()
