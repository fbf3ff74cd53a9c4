"""Clean child processes, quickly: multiprocessing's fork server, shared by an FMU's own process
(fmu.child), the workers of runs and data collection (cosim.executor) and of trainings
(learning.workers).

A fork of the caller itself would copy its threads' state (torch's and BLAS's pools, an FMU's
threads) and its CUDA context, which a child cannot use; Python 3.12 warns of it, and 3.14 no
longer forks by default. The fork server is started once, single-threaded, and first imports
the flexff modules the caller has imported by then (`context`), so that a child starts in
milliseconds with them loaded. Its children have the environment and working folder of the
server's start; each takes the caller's of the moment, and ends with the caller
(`Caller.adopt`).
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from dataclasses import dataclass
from multiprocessing.context import ForkServerContext

from flexff.fmu.orphans import die_with

PACKAGE = "flexff"


def context(*modules: str) -> ForkServerContext:
    """The fork server's context. The server, if this call starts it, imports `modules` and
    every flexff module imported here by now (those already started keep their imports; a
    child imports what else it needs)."""
    loaded = sorted(name for name in sys.modules if (name == PACKAGE or name.startswith(
        PACKAGE + ".")) and not name.endswith(".__main__"))  # the command line runs on import
    fork_server = multiprocessing.get_context("forkserver")
    fork_server.set_forkserver_preload([*loaded, *modules])
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
        """In a child of the fork server: end with the caller (fmu.orphans), take its
        environment and folder."""
        die_with(self.pid)
        os.environ.clear()
        os.environ.update(self.environment)
        os.chdir(self.folder)
