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

from flexff.fmu.printable import printable

LINE_CHARS = 1000  # the most of one line shown
LIMIT_BYTES = 256 << 10  # what is shown of one FMU's output, at most
CHUNK = 1 << 16


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
