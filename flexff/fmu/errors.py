"""The error classes the command line tells apart (flexff.cli exits with a code per class).

InputError: bad input, the user's to fix (exit 2); RunError: a run that failed for a reason
outside the program, e.g. an FMU or a compiler that failed (exit 1); MissingPackage: an optional
package to install (exit 1). Terminated: SIGTERM, handled as Ctrl-C is (exit 143). Anything else
is a bug: exit 1 and a hint to rerun with --debug.
"""

from pathlib import Path

# what str.splitlines breaks lines at, each written as its escape (\n, \x85, \u2028)
_LINE_BREAKS = str.maketrans({c: repr(c)[1:-1] for c in "\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029"})


def one_line(text: str) -> str:
    """`text` with its line breaks written as escapes: a message that quotes a name from the
    input (a TOML key, a CSV column, an XML attribute) stays the one line the CLI prints."""
    return text.translate(_LINE_BREAKS)


def not_a_file(path: Path, what: str = "file") -> str | None:
    """Why `path` is no file ("no such <what>", or the system's reason for a path it cannot
    look up, such as a name too long), None where it is one."""
    try:
        return None if path.is_file() else f"no such {what}"
    except OSError as error:
        return f"cannot look up the {what}: {error.strerror or error}"


class InputError(ValueError):
    """Bad input: a configuration, a path, an option, a file's contents (an FMU, an ONNX model,
    a dataset); the message says what is wrong and where, on one line (one_line: whatever
    names it quotes). The CLI exits 2 with its message."""

    def __str__(self) -> str:
        return one_line(super().__str__())


class RunError(RuntimeError):
    """A run that failed for a reason outside the program (an FMU's error, a failed compiler,
    training that diverged); the CLI exits 1 with its message."""


class MissingPackage(RunError, ImportError):
    """An optional package is not installed; the message says what to pip install."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread (flexff.cli) so that it ends a command as Ctrl-C
    does: temporary folders removed, the record kept, one line saying what was kept."""
