"""The memory a run is about to allocate, checked before it does: an impossible run (a stop
of 10^7 s, a step of a nanosecond) is a clear error, not a MemoryError after minutes of work."""

from __future__ import annotations

import os

from flexff.fmu.errors import InputError


class MemoryNeeded(InputError):
    """Values that would not fit into the available memory, found before allocating them."""


def available_memory() -> int:
    """Bytes of memory a new allocation can take without swapping (psutil's estimate, which
    counts reclaimable caches; else the free pages)."""
    try:
        import psutil
    except ImportError:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(psutil.virtual_memory().available)


def check_memory(values: int, what: str) -> None:
    """Raise MemoryNeeded when `values` float64 numbers do not fit into the available memory;
    `what` names them in the message."""
    need, have = 8 * values, available_memory()
    if need > have:
        raise MemoryNeeded(f"{what} needs {need / 1e6:,.0f} MB, more than the "
                           f"{have / 1e6:,.0f} MB of memory available")
