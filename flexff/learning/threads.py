"""How many CPU threads torch uses here, and a context to set them for a while.

The networks' operations are small (one LSTM step, a 100-sample window). On a machine whose
cores are also busy with other work, a thread that waits for a core stalls every operation:
measured on two shared cores, one TCN batch took 16 ms on one thread and 750 ms on two, one
small LSTM chunk 7.5 ms against 2.6 s. So the default is half the cores granted, at least one;
more only pay where the cores are free, and `threads` in the training configuration sets them.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch

from flexff.cosim.executor import granted_cores


def cpu_threads(requested: int = 0) -> int:
    """`requested`, or by default half the cores granted to this process (at least one)."""
    return requested or max(1, granted_cores() // 2)


@contextmanager
def torch_threads(requested: int = 0) -> Iterator[int]:
    """Run the block with `cpu_threads(requested)` torch threads; restore the count after."""
    previous = torch.get_num_threads()
    torch.set_num_threads(cpu_threads(requested))
    try:
        yield torch.get_num_threads()
    finally:
        torch.set_num_threads(previous)
