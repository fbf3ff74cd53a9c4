"""Child processes that die with their parent: an FMU's process (cosim.isolation, fmu.child)
and a pool's worker (cosim.executor, learning.workers) ask the kernel for SIGKILL when their
parent ends (Linux's PR_SET_PDEATHSIG), so that a master killed while its FMU hangs or spins
does not leave the FMU running under init forever, nor a worker blocked on a queue.

The request holds from the moment it is made; a parent that ended before that is found by its
pid, which the child then no longer has for its parent. The kernel sends the signal when the
parent's thread that started the child ends: a master starts its children from the thread that
runs it. Elsewhere than on Linux nothing is asked for, and where the kernel refuses (a sandbox
that filters prctl) the child lives on as before.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent: int) -> None:
    """Have this process killed when its parent `parent` (a pid) ends; end it now if the
    parent has already ended."""
    if not sys.platform.startswith("linux"):
        return
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # best effort
    if os.getppid() != parent:
        os._exit(1)
