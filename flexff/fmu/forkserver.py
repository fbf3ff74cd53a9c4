"""Clean child processes, quickly: multiprocessing's fork server, shared by an FMU's own process
(fmu.child), trainings (learning.workers) and other fresh workers (cosim.executor).

A fork of the caller itself would copy its threads' state (torch's and BLAS's pools, an FMU's
threads) and its CUDA driver state, which a child cannot use safely; Python 3.12 warns of it,
and 3.14 no longer forks by default. The fork server is started once, single-threaded, and
first imports what its first user asks for (`context`), so that a child starts in milliseconds
with that loaded; a child imports what else it needs. Only what is asked for: a library such
as onnxruntime, once imported, hangs a forked child that calls exit(), as an FMU may. Each
child takes the caller's environment and working folder of the moment, and ends with the
caller (`Caller.adopt`). As with any start but a fork, each child first imports the caller's
main script, which therefore keeps its top level under `if __name__ == "__main__":`.
"""

from __future__ import annotations

import multiprocessing
import os
from dataclasses import dataclass
from multiprocessing.context import ForkServerContext

from flexff.fmu.orphans import die_with


def context(*modules: str) -> ForkServerContext:
    """The fork server's context; the server, if this call starts it, first imports `modules`
    (one started before keeps what it imported)."""
    fork_server = multiprocessing.get_context("forkserver")
    fork_server.set_forkserver_preload(list(modules))
    return fork_server


@dataclass(frozen=True)
class Caller:
    """What a child takes of its caller: the environment and the working folder, and its end."""

    environment: dict[str, str]
    folder: str
    pid: int

    @classmethod
    def now(cls) -> Caller:
        """This process, with its environment and working folder as they are now."""
        return cls(dict(os.environ), os.getcwd(), os.getpid())

    def adopt(self) -> None:
        """In a child (a fork server's, or a fork): end with the caller (fmu.orphans), take
        its environment and folder."""
        die_with(self.pid)
        os.environ.clear()
        os.environ.update(self.environment)
        os.chdir(self.folder)
