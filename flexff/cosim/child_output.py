"""What an isolated FMU's process prints (its stdout and stderr, one pipe; cosim.isolation),
relayed to flexff's stderr by a thread of the master: each line escaped (fmu.printable: no
control character reaches the terminal), cut at LINE_CHARS and marked as the FMU's, so that
none passes for a line of flexff's own; after LIMIT_BYTES the rest is read and dropped, with
one line saying so. The FMU never holds the user's terminal or log file: it can neither type
into the one nor truncate or flood the other."""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable

from flexff.fmu.printable import printable

LINE_CHARS = 1000  # the most of one line shown
LIMIT_BYTES = 256 << 10  # what is shown of one FMU's output, at most
CHUNK = 1 << 16
MESSAGE_CHARS = 1 << 20  # the most of one log message written to the run's log file


class _PipeLines:
    """Reads the pipe `fd` (and closes it) until its end, in a thread named `thread`, handing
    each line (without its newline; one of more than `longest` bytes cut there) to `_line`;
    once `ignoring`, the rest is read and dropped."""

    ignoring = False

    def __init__(self, fd: int, thread: str, longest: int) -> None:
        self.fd, self.longest = fd, longest
        self.thread = threading.Thread(target=self._relay, name=thread, daemon=True)
        self.thread.start()

    def _line(self, line: bytes) -> None:
        raise NotImplementedError

    def _relay(self) -> None:
        pending = bytearray()
        try:
            while chunk := os.read(self.fd, CHUNK):
                if self.ignoring:
                    continue
                pending += chunk
                while not self.ignoring and ((end := pending.find(b"\n")) >= 0
                                             or len(pending) > self.longest):
                    cut = end if end >= 0 else self.longest
                    self._line(bytes(pending[:cut]))
                    del pending[:cut + (end >= 0)]
            if pending and not self.ignoring:
                self._line(bytes(pending))
        except OSError:
            pass
        finally:
            os.close(self.fd)

    def join(self, timeout: float) -> None:
        """Wait until the pipe is read to its end (the process and its threads gone)."""
        self.thread.join(timeout)


class OutputRelay(_PipeLines):
    """What the isolated FMU `name`'s process prints, each line shown on stderr as
    `NAME| line` (module doc)."""

    def __init__(self, fd: int, name: str) -> None:
        self.name, self.shown = name, 0
        super().__init__(fd, f"output of {name}", LINE_CHARS)

    def _line(self, line: bytes) -> None:
        self.shown += len(line) + 1
        if self.shown > LIMIT_BYTES:
            self.ignoring = True
            text = f"{self.name}| (its further output dropped: more than {LIMIT_BYTES} bytes)"
        else:
            text = f"{self.name}| {printable(line.decode('utf-8', 'replace'), LINE_CHARS)}"
        print(text, file=sys.stderr, flush=True)


class MessageRelay(_PipeLines):
    """The isolated FMU `name`'s log messages, one a line, each handed to `log` as
    `name: message` (the name the master's, not the child's), a line cut at MESSAGE_CHARS:
    they reach the run's log file (cosim.fmu_log) as an in-process FMU's do, and the child
    keeps none."""

    def __init__(self, fd: int, name: str, log: Callable[[str], None]) -> None:
        self.name, self.log = name, log
        super().__init__(fd, f"log of {name}", MESSAGE_CHARS)

    def _line(self, line: bytes) -> None:
        self.log(f"{self.name}: {line.decode('utf-8', 'replace')}")


def message_writer(fd: int) -> Callable[[str], None]:
    """In the child: a MessageLog writer (fmu.messages) that sends each message, its line
    breaks escaped, as one line on the pipe `fd` to the master's MessageRelay; it never
    raises (a master gone, or a pipe closed: the message is dropped)."""
    def write(line: str) -> None:
        data = (line.partition(": ")[2].replace("\n", "\\n") + "\n").encode()
        try:
            while data:
                data = data[os.write(fd, data):]
        except OSError:
            pass
    return write
