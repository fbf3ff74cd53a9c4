"""Windows, the validation split and mini-batches over prepared trajectories.

Training trajectories are cut into consecutive windows of `window` samples; a seeded shuffle
of all windows picks the validation share (the thesis holds out 12.5 % of its training data).
Every sample carries a role: train, validation or padding. The networks always run over
whole trajectories or consecutive chunks of them, so the recurrent state and the
convolutions' history are those of deployment; a sample's role only decides which loss it
enters.

Recurrent networks train by truncated backpropagation through time: a batch of trajectories
runs chunk by chunk (`window` samples), the state carried across chunks and detached, so
gradients reach back at most one chunk. Convolutional networks train on random windows: the
`window` outputs of one window plus the `history` inputs before it (zeros before the start,
as the zero initial buffer at deployment).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch

from flexff.fmu.errors import InputError

PAD, TRAIN, VALIDATION = 0, 1, 2
# (history x, window x, window y, window mask) of a batch of windows
Batch = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


def window_roles(lengths: list[int], window: int, val_fraction: float,
                 rng: np.random.Generator, edge: int = 0) -> list[np.ndarray]:
    """Per trajectory, the role of each sample (TRAIN or VALIDATION), by whole windows; the
    first and last `edge` samples PAD (see `interior`), and only windows with samples
    between them drawn for validation."""
    roles = [interior(n, edge) for n in lengths]
    blocks = [(i, start) for i, r in enumerate(roles) for start in range(0, len(r), window)
              if (r[start:start + window] == TRAIN).any()]
    n_val = round(val_fraction * len(blocks))
    if n_val < 1 or n_val >= len(blocks):
        raise InputError(
            f"the training trajectories give {len(blocks)} window(s) of {window} samples, too few "
            f"to hold out {val_fraction:.1%} for validation: collect more or longer training "
            f"trajectories, or lower `window`")
    for k in rng.permutation(len(blocks))[:n_val]:
        i, start = blocks[k]
        block = roles[i][start:start + window]
        block[block == TRAIN] = VALIDATION
    return roles


def interior(length: int, edge: int) -> np.ndarray:
    """The roles of a trajectory of `length` samples: TRAIN, but its first and last `edge`
    samples PAD. The network still runs over those (its state and history warm up there), but
    they enter no loss: there the zero-phase filter's start and end transients make motion
    and force disagree (learning.features)."""
    roles = np.full(length, TRAIN, dtype=np.int64)
    roles[:edge] = PAD
    roles[max(length - edge, 0):] = PAD
    return roles


@dataclass
class SequenceSet:
    """Trajectories padded to one length: x (n, T, F), y (n, T, 2), role (n, T), on a device."""

    x: torch.Tensor
    y: torch.Tensor
    role: torch.Tensor

    @classmethod
    def build(cls, xs: list[np.ndarray], ys: list[np.ndarray], roles: list[np.ndarray],
              device: torch.device) -> SequenceSet:
        length = max(len(x) for x in xs)
        x = np.zeros((len(xs), length, xs[0].shape[1]), dtype=np.float32)
        y = np.zeros((len(xs), length, ys[0].shape[1]), dtype=np.float32)
        role = np.full((len(xs), length), PAD, dtype=np.int64)
        for i, (xi, yi, ri) in enumerate(zip(xs, ys, roles)):
            x[i, :len(xi)], y[i, :len(yi)], role[i, :len(ri)] = xi, yi, ri
        return cls(torch.from_numpy(x).to(device), torch.from_numpy(y).to(device),
                   torch.from_numpy(role).to(device))

    def __len__(self) -> int:
        return self.x.shape[0]

    def groups(self, batch_size: int, rng: np.random.Generator
               ) -> list[tuple[np.ndarray, torch.Tensor]]:
        """The trajectory indices in shuffled groups of at most batch_size, each on the host
        and on the data's device (one copy per call, none per group)."""
        order = rng.permutation(len(self))
        on_device = torch.as_tensor(order, device=self.x.device)
        return list(zip(np.array_split(order, range(batch_size, len(order), batch_size)),
                        on_device.split(batch_size)))


class WindowSampler:
    """Random windows of the TRAIN samples for convolutional networks.

    Each item is (history (B, history, F), x (B, window, F), y (B, window, 2), mask (B, window)).
    Everything stays on the data's device: an epoch copies only its shuffled order there.
    """

    def __init__(self, data: SequenceSet, window: int, history: int) -> None:
        self.data, self.window, self.history = data, window, history
        role = data.role.cpu().numpy()
        starts = [(i, s) for i in range(len(data)) for s in range(0, role.shape[1], window)
                  if (role[i, s:s + window] == TRAIN).any()]
        # (trajectory, first sample) of each window
        self._starts = torch.as_tensor(starts, dtype=torch.int64, device=data.x.device)
        n, _, width = data.x.shape
        self._x = torch.cat([data.x.new_zeros(n, history, width), data.x,
                             data.x.new_zeros(n, window, width)], dim=1)
        self._y = torch.cat([data.y, data.y.new_zeros(n, window, data.y.shape[2])], dim=1)
        self._mask = torch.cat([data.role == TRAIN,
                                data.role.new_zeros(n, window, dtype=torch.bool)], dim=1)

    def batches(self, batch_size: int, rng: np.random.Generator) -> Iterator[Batch]:
        """Yield shuffled batches covering every training window once."""
        order = torch.as_tensor(rng.permutation(len(self)), device=self._x.device)
        span = torch.arange(self.history + self.window, device=self._x.device)
        for items in self._starts[order].split(batch_size):
            traj, start = items[:, 0], items[:, 1]
            x = self._x[traj[:, None], start[:, None] + span]
            out = start[:, None] + span[:self.window]
            yield (x[:, :self.history], x[:, self.history:], self._y[traj[:, None], out],
                   self._mask[traj[:, None], out])

    def __len__(self) -> int:
        return len(self._starts)
