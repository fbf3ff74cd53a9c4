"""Which torch device training runs on, and how many trainings share the machine.

A network of either preset is small: on an H200 one training kept the GPU busy 10 to 30 % of
the time (flexff bench --training, docs/results/training), the rest going to the host's
launches. So trainings side by side share each GPU, TRAININGS_PER_GPU processes of them
(learning.workers), and take one process per core on the CPU; data collection and
co-simulation use every core either way.
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
