"""A run's FMU log file: every message of its in-process FMUs, one line each (`instance:
[status] message`), written as it comes rather than held (fmu.messages), so that a chatty FMU's
log takes disk, not memory. The file is created by the first message (a run refused before it
starts leaves none). A write that fails (a full disk) ends the log, not the run; closing it then
warns once, naming the file."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TextIO

LOG_NAME = "fmu.log"  # in the run's folder


class FmuLog:
    """The log file `path`, written from its first line on (emptied then); use it as a context
    manager."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.error: OSError | None = None  # the write that ended the log
        self._file: TextIO | None = None
        self._closed = False

    def forget_earlier(self) -> None:
        """Remove an earlier run's log, unless this one has begun (the run has started)."""
        if self._file is None:
            self.path.unlink(missing_ok=True)

    def write(self, line: str) -> None:
        """Append one line (given without its newline); never raises (it is called from an
        FMU's logger), a failed write ends the log, and one after `close` is dropped."""
        if self.error is not None or self._closed:
            return
        try:
            if self._file is None:
                self._file = open(self.path, "w", encoding="utf-8", errors="replace")  # noqa: SIM115
            self._file.write(line + "\n")
        except OSError as error:
            self.error = error

    def close(self) -> None:
        """Flush and close the file (safe twice); warn where a write failed."""
        if self._closed:
            return
        self._closed = True
        if self._file is not None:
            try:
                self._file.close()
            except OSError as error:
                self.error = self.error or error
        if self.error is not None:
            warnings.warn(f"{self.path}: {self.error.strerror or self.error}: the FMUs' "
                          f"messages from there on are not in it", stacklevel=2)

    def __enter__(self) -> FmuLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
