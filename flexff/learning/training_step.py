"""One optimizer step of training, run eagerly or replayed from a CUDA graph.

The networks are small (35k to 90k parameters, batches of 32): on a GPU an eager step spends
its time launching kernels from Python, not in them (the H200 was busy 13 to 30 % of an
epoch; flexff bench --training). On CUDA, where asked (`cuda_graphs`), a `TrainingStep`
therefore captures the whole step (forward, masked MSE, backward, gradient clipping, Adam)
once per input shape as a CUDA graph and replays it: the host copies the batch into the
graph's inputs and launches one graph. Each shape's first step runs eagerly (it creates the
optimizer's state and the libraries' workspaces, which a capture must not), its second is
captured and replayed. Adam runs `capturable`, its learning rate a device tensor that the
schedule sets between replays. Where a capture fails, the steps run eagerly after one
warning.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch

from flexff.learning.models import SequenceNetwork, State

Step = Callable[[], None]  # runs the step on the captured inputs
StepResult = tuple[torch.Tensor, State]  # the loss and the state after the inputs, detached


def adam(network: SequenceNetwork, learning_rate: float, captured: bool) -> torch.optim.Adam:
    """Adam over the network's parameters; for a captured step capturable, its learning
    rate a tensor on the parameters' device."""
    if not captured:
        return torch.optim.Adam(network.parameters(), lr=learning_rate)
    device = next(network.parameters()).device
    return torch.optim.Adam(network.parameters(), lr=torch.tensor(learning_rate, device=device),
                            capturable=True, foreach=True)


def set_learning_rate(optimizer: torch.optim.Optimizer, value: float) -> None:
    """Set every group's learning rate: in place where it is a tensor a graph reads."""
    for group in optimizer.param_groups:
        if isinstance(group["lr"], torch.Tensor):
            group["lr"].fill_(value)
        else:
            group["lr"] = value


def portable_state(optimizer: torch.optim.Optimizer) -> dict[str, Any]:
    """The optimizer's state dict as a plain Adam on any device loads it: the learning rate a
    number, not capturable (`load_state` makes it so again where a step is captured)."""
    state = optimizer.state_dict()
    state["param_groups"] = [{**group, "lr": float(group["lr"]), "capturable": False}
                             for group in state["param_groups"]]
    return state


def load_state(optimizer: torch.optim.Adam, state: dict[str, Any], captured: bool) -> None:
    """Load a `portable_state` written on any device into `optimizer`, made by `adam` with
    `captured`: a captured step's Adam keeps its learning-rate tensor and its step counts on
    the device; a plain one's step counts live on the host."""
    lrs = [group["lr"] for group in optimizer.param_groups]
    optimizer.load_state_dict(state)
    for group, lr in zip(optimizer.param_groups, lrs):
        group["capturable"] = captured
        if captured:
            lr.fill_(float(group["lr"]))
            group["lr"] = lr
        for param in group["params"]:
            if "step" in optimizer.state[param]:
                step = optimizer.state[param]["step"]
                optimizer.state[param]["step"] = step.to(
                    param.device if captured else "cpu", torch.float32)


@dataclass
class _Graph:
    """The inputs a captured step reads, its outputs, and how to run it."""

    inputs: list[torch.Tensor]
    outputs: StepResult
    run: Step


class CudaGraphs:
    """Warm-ups and captures on one side stream of the current CUDA device (a capture reuses
    the workspaces that a warm-up on its stream created)."""

    def __init__(self) -> None:
        self.stream = torch.cuda.Stream()  # type: ignore[no-untyped-call]

    def warm_up(self, work: Callable[[], StepResult]) -> StepResult:
        """Run `work` eagerly on the side stream, ordered after and before the current one."""
        current = torch.cuda.current_stream()
        self.stream.wait_stream(current)
        with torch.cuda.stream(self.stream):
            result = work()
        current.wait_stream(self.stream)
        return result

    def capture(self, work: Callable[[], StepResult]) -> tuple[StepResult, Step]:
        """Capture `work` (nothing runs yet): its outputs, and the graph's replay."""
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph, stream=self.stream):
            outputs = work()
        return outputs, graph.replay


class TrainingStep:
    """`step(x, state, target, mask)`: one optimizer step of `network` on the masked MSE of
    its outputs for inputs x (batch, time, features) from `state` against `target`
    (batch, time, outputs); returns the loss, detached, and the state after x, detached.
    With `graphs`, each input shape's step is captured from its second call on.

    The outputs of a captured step are the graph's own tensors: the next replay of the same
    shape overwrites them, so use them (or copy them) before the next step."""

    def __init__(self, network: SequenceNetwork, optimizer: torch.optim.Optimizer,
                 grad_clip: float, graphs: CudaGraphs | None) -> None:
        self.network, self.optimizer, self.grad_clip = network, optimizer, grad_clip
        self.graphs = graphs
        self._captured: dict[tuple[tuple[int, ...], ...], _Graph | None] = {}

    def __call__(self, x: torch.Tensor, state: State, target: torch.Tensor,
                 mask: torch.Tensor) -> StepResult:
        tensors = [x, *state, target, mask]
        if self.graphs is None:
            return self._step(*tensors)
        key = tuple(tuple(t.shape) for t in tensors)
        if key not in self._captured:  # the shape's first step
            self._captured[key] = None
            return self.graphs.warm_up(lambda: self._step(*tensors))
        graph = self._captured[key] or self._capture(key, tensors)
        if graph is None:  # the capture failed: eager from now on
            return self._step(*tensors)
        for static, given in zip(graph.inputs, tensors):
            static.copy_(given)
        graph.run()
        return graph.outputs

    def _step(self, x: torch.Tensor, *rest: torch.Tensor) -> StepResult:
        *state, target, mask = rest
        self.optimizer.zero_grad(set_to_none=True)
        pred, new_state = self.network(x, tuple(state))
        loss = masked_mse(pred, target, mask)
        loss.backward()
        if self.grad_clip:
            torch.nn.utils.clip_grad_norm_(self.network.parameters(), self.grad_clip)
        self.optimizer.step()
        return loss.detach(), tuple(s.detach() for s in new_state)

    def _capture(self, key: tuple[tuple[int, ...], ...], tensors: list[torch.Tensor]
                 ) -> _Graph | None:
        """Capture the step of `key`'s shapes on copies of `tensors`; None (one warning, and
        eager steps from then on) where the capture fails."""
        assert self.graphs is not None
        inputs = [t.clone() for t in tensors]
        try:
            outputs, run = self.graphs.capture(lambda: self._step(*inputs))
        except RuntimeError as error:
            warnings.warn(f"training steps run eagerly: their capture as a CUDA graph failed "
                          f"({str(error).splitlines()[0]})", RuntimeWarning, stacklevel=3)
            self.graphs = None
            return None
        self._captured[key] = _Graph(inputs, outputs, run)
        return self._captured[key]


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared error over the samples where mask is true (both outputs)."""
    weight = mask.unsqueeze(-1).to(pred.dtype)
    return ((pred - target) ** 2 * weight).sum() / (weight.sum() * pred.shape[-1])
