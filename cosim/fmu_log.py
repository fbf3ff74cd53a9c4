"""A run's FMU log file: every message of its in-process FMUs, one line each (`instance:
[status] message`), written as it comes rather than held (fmu.messages), so that a chatty FMU's
log takes disk, not memory. A write that fails (a full disk) ends the log, not the run; closing
it then warns once, naming the file."""

from __future__ import annotations

import warnings
from pathlib import Path

LOG_NAME = "fmu.log"  # in the run's folder


class FmuLog:
    """The log file `path`, opened (and emptied) now; use it as a context manager."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.lines = 0  # lines written
        self.error: OSError | None = None  # the write that ended the log
        self._file = open(path, "w", encoding="utf-8", errors="replace")  # noqa: SIM115 (held)

    def write(self, line: str) -> None:
        """Append one line (given without its newline); never raises (it is called from an
        FMU's logger), a failed write ends the log."""
        if self.error is not None:
            return
        try:
            self._file.write(line + "\n")
            self.lines += 1
        except OSError as error:
            self.error = error

    def close(self) -> None:
        """Flush and close the file (safe twice); warn where a write failed."""
        if self._file.closed:
            return
        try:
            self._file.close()
        except OSError as error:
            self.error = self.error or error
        if self.error is not None:
            warnings.warn(f"{self.path}: {self.error.strerror or self.error}: the FMUs' "
                          f"messages after its first {self.lines} lines are not in it",
                          stacklevel=2)

    def __enter__(self) -> FmuLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
