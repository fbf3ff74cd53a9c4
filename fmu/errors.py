"""The error classes the command line tells apart (flexff.cli exits with a code per class).

InputError: bad input, the user's to fix (exit 2); RunError: a run that failed for a reason
outside the program, e.g. an FMU or a compiler that failed (exit 1); MissingPackage: an optional
package to install (exit 1). Terminated: SIGTERM, handled as Ctrl-C is (exit 143). Anything else
is a bug: exit 1 and a hint to rerun with --debug.
"""


class InputError(ValueError):
    """Bad input: a configuration, a path, an option, a file's contents (an FMU, an ONNX model,
    a dataset); the message says what is wrong and where. The CLI exits 2 with its message."""


class RunError(RuntimeError):
    """A run that failed for a reason outside the program (an FMU's error, a failed compiler,
    training that diverged); the CLI exits 1 with its message."""


class MissingPackage(RunError, ImportError):
    """An optional package is not installed; the message says what to pip install."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread (flexff.cli) so that it ends a command as Ctrl-C
    does: temporary folders removed, the record kept, one line saying what was kept."""
