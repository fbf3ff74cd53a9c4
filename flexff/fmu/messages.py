"""An FMU instance's log messages: each handed to a writer as it comes (a run's log file, where
there is one), the last TAIL kept for error messages, so that the log of a chatty FMU costs
memory that does not grow with the run."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

TAIL = 20  # messages kept in memory (an error message names the last few)


class MessageLog:
    """The messages of the instance `name`: every one given to `write` (as the line
    `name: message`, without its newline), the last TAIL in `tail`."""

    def __init__(self, name: str, write: Callable[[str], None] | None = None) -> None:
        self.name, self.write = name, write
        self.tail: deque[str] = deque(maxlen=TAIL)
        self.count = 0  # messages received

    def append(self, message: str) -> None:
        """Take one message (called from the FMU's logger: `write` must not raise)."""
        self.tail.append(message)
        self.count += 1
        if self.write is not None:
            self.write(f"{self.name}: {message}")

    def last(self, n: int) -> list[str]:
        """The last `n` messages (fewer where there were fewer), oldest first."""
        return list(self.tail)[-n:]
