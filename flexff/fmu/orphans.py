"""Child processes that die with the process that started them: an FMU's process
(cosim.isolation, fmu.child) and a pool's worker (cosim.executor, learning.workers), so that a
master killed while its FMU hangs or spins does not leave the FMU running forever, nor a worker
blocked on a queue.

A child of its starter asks the kernel for SIGKILL when its parent ends (Linux's
PR_SET_PDEATHSIG); the kernel sends it when the parent's thread that started the child ends: a
master starts its children from the thread that runs it. A child of the fork server
(fmu.forkserver) has the server for its parent, which lives as long as any of its children, so
it waits for its starter's end in a thread of its own (a pidfd) and then kills itself. A
starter that ended before the request is found at once. Elsewhere than on Linux nothing is
asked for, and where the kernel refuses (a sandbox that filters prctl or pidfds) the child
lives on as before.
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
import sys
import threading

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with(starter: int) -> None:
    """Have this process killed when the process `starter` (a pid) ends; end it now if
    `starter` has already ended."""
    if not sys.platform.startswith("linux"):
        return
    if os.getppid() == starter:
        ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # best effort
        if os.getppid() != starter:  # it ended before the request
            os._exit(1)
        return
    try:
        ended = os.pidfd_open(starter)
    except ProcessLookupError:
        os._exit(1)
    except OSError:  # refused: live on
        return
    threading.Thread(target=_die_when_readable, args=(ended,), daemon=True,
                     name="die with the starter").start()


def _die_when_readable(pidfd: int) -> None:
    """Wait for the process behind `pidfd` to end, then SIGKILL this one, as the kernel does a
    child whose parent ended."""
    select.select([pidfd], [], [])
    os.kill(os.getpid(), signal.SIGKILL)
