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


class OutputRelay:
    """Reads the pipe `fd` (and closes it) until its end, in a thread, showing each line on
    stderr as `NAME| line`."""

    def __init__(self, fd: int, name: str) -> None:
        self.fd, self.name = fd, name
        self.shown = 0
        self.dropped = False
        self.thread = threading.Thread(target=self._relay, name=f"output of {name}", daemon=True)
        self.thread.start()

    def _relay(self) -> None:
        pending = bytearray()
        try:
            while chunk := os.read(self.fd, CHUNK):
                if self.dropped:
                    continue
                pending += chunk
                while not self.dropped and ((end := pending.find(b"\n")) >= 0
                                            or len(pending) > LINE_CHARS):
                    cut = end if end >= 0 else LINE_CHARS
                    self._show(bytes(pending[:cut]))
                    del pending[:cut + (end >= 0)]
            if pending and not self.dropped:
                self._show(bytes(pending))
        except OSError:
            pass
        finally:
            os.close(self.fd)

    def _show(self, line: bytes) -> None:
        self.shown += len(line) + 1
        if self.shown > LIMIT_BYTES:
            self.dropped = True
            text = f"{self.name}| (its further output dropped: more than {LIMIT_BYTES} bytes)"
        else:
            text = f"{self.name}| {printable(line.decode('utf-8', 'replace'), LINE_CHARS)}"
        print(text, file=sys.stderr, flush=True)

    def join(self, timeout: float) -> None:
        """Wait until the pipe is read to its end (the process and its threads gone)."""
        self.thread.join(timeout)


class MessageRelay:
    """Reads the pipe `fd` (and closes it) until its end, in a thread: each line one log
    message of the isolated FMU `name`, handed to `log` as `name: message` (the name the
    master's, not the child's), a line cut at MESSAGE_CHARS; the FMU's log messages reach the
    run's log file (cosim.fmu_log) as an in-process FMU's do, and the child keeps none."""

    def __init__(self, fd: int, name: str, log: Callable[[str], None]) -> None:
        self.fd, self.name, self.log = fd, name, log
        self.thread = threading.Thread(target=self._relay, name=f"log of {name}", daemon=True)
        self.thread.start()

    def _relay(self) -> None:
        pending = bytearray()
        try:
            while chunk := os.read(self.fd, CHUNK):
                pending += chunk
                while (end := pending.find(b"\n")) >= 0 or len(pending) > MESSAGE_CHARS:
                    cut = end if end >= 0 else MESSAGE_CHARS
                    self.log(f"{self.name}: {pending[:cut].decode('utf-8', 'replace')}")
                    del pending[:cut + (end >= 0)]
            if pending:
                self.log(f"{self.name}: {pending.decode('utf-8', 'replace')}")
        except OSError:
            pass
        finally:
            os.close(self.fd)

    def join(self, timeout: float) -> None:
        """Wait until the pipe is read to its end (the process gone)."""
        self.thread.join(timeout)


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
