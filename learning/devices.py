"""Which torch device training runs on, and how many trainings share the machine.

A network of the fast preset is small: on a GPU one training keeps its device busy, and
several processes each starting CUDA on the same GPU only contend for it (and for its
memory). So trainings side by side get one process per GPU there, one per core on the CPU
(learning.workers); data collection and co-simulation use every core either way.
"""

from __future__ import annotations

import torch

from flexff.fmu.errors import InputError

DEVICES = ("auto", "cpu", "cuda")  # what --device offers; "cuda:N" names one GPU


def pick_device(name: str) -> torch.device:
    """'auto': CUDA when available, else CPU; or the named device (InputError naming what to
    ask for instead if it is CUDA and CUDA is not available)."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"device {name!r} asked for, but CUDA is not available here: use "
                         f"--device cpu or auto")
    try:
        return torch.device(name)
    except RuntimeError:
        raise InputError(f"unknown device {name!r}: choose one of {', '.join(DEVICES)}") \
            from None


def training_gpus(device: torch.device) -> list[int]:
    """The GPUs trainings on `device` run on, one process each: the one it names, or every
    GPU for plain 'cuda'; none for another device."""
    if device.type != "cuda":
        return []
    return [device.index] if device.index is not None else list(range(torch.cuda.device_count()))
