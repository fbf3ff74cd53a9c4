"""A trained run as a model in SI units: what the exported ONNX graph computes.

Scaling and unscaling live inside the module: features in SI units in, forces in newtons out.
For the pgnn it adds the residual to its rigid-body prior (or, with `prior=False`, returns the
residual alone). With `inputs="reference"` it computes the features (and a black-box
network's force inputs) from the reference in the graph. A machine's linear skip, and that of
a network with force inputs, is exported beside the graph as `linear_map` (`skip_outside`),
for the feedforward FMU to add at the loop's rate. The pgnn's residual fades
to zero beyond the training range (TRUST_FADE), so there the model falls back on its prior;
a machine's pgnn fades its network so, not the skip beside the graph.

Docs: "The learned feedforward FMU" (docs/explanation/learned-feedforward-fmu.md).
"""

from __future__ import annotations

from typing import cast

import numpy as np
import torch
from torch import nn

from flexff.fmu.errors import InputError
from flexff.learning.casadi_torch import TorchFunction
from flexff.learning.feature_spec import feature_units as machine_feature_units
from flexff.learning.implicit_machine import implicit_machine
from flexff.learning.model_card import INPUT_KINDS
from flexff.learning.models import LinearSkip, uses_prior
from flexff.learning.rigid import RigidBodyForce
from flexff.learning.run_folder import Run
from flexff.learning.threads import torch_threads

TRUST_FADE = 0.5  # training spans beyond the range over which the pgnn's residual fades out


def trust(scaled: torch.Tensor) -> torch.Tensor:
    """Features (T, n) scaled to their training range [0, 1] -> (T, 1): 1 inside the range,
    falling linearly to 0 at TRUST_FADE spans beyond it, by the farthest feature."""
    beyond = (torch.relu(-scaled) + torch.relu(scaled - 1.0)).amax(dim=1, keepdim=True)
    return torch.clamp(1.0 - beyond / TRUST_FADE, 0.0, 1.0)


class SIModel(nn.Module):
    """(inputs (T, n_inputs), *state) -> (forces (T, 2) [N], or currents (T, 3) [A] for a
    current-level run, *new state).

    Inputs and forces are float64, and so is everything outside the network (features from the
    reference, scaling, the rigid-body prior): some features sit far from zero with a tiny
    training span (theta_ee: 1.309 rad +- 0.5 mrad), which float32 would resolve to only 1e-4
    of the span. The network and its state (batch size 1, zeros at the start) are float32.
    """

    # the scalers' buffers (register_buffer in __init__)
    feature_low: torch.Tensor
    feature_span: torch.Tensor
    label_low: torch.Tensor
    label_span: torch.Tensor

    def __init__(self, run: Run, inputs: str = "features", prior: bool = True,
                 skip_outside: bool = False) -> None:
        super().__init__()
        if inputs not in INPUT_KINDS:
            raise InputError(f"inputs must be one of {INPUT_KINDS}, got {inputs!r}")
        feature_set = run.config.features.feature_set
        self.network = run.network.eval()
        self.linear_map: tuple[np.ndarray, np.ndarray] | None = None
        if skip_outside and isinstance(self.network, LinearSkip):
            self.linear_map = _si_skip(self.network, run, not uses_prior(run.config.model))
            self.network = self.network.network
        self.inputs = inputs
        by_reference = inputs == "reference"
        machine = run.machine
        if machine is not None and by_reference:
            raise InputError(f"{run.path}: a machine's model takes its features; the "
                             f"feedforward FMU computes them from the reference")
        self.force_input = run.force_input
        self.input_names: list[str] = run.feature_names
        self.reference: TorchFunction | None = None
        if machine is not None:
            self.input_units = machine_feature_units(machine, run.feature_inputs)
        else:  # a run without a machine description: the implicit machine's signals
            implicit = implicit_machine()
            self.input_units = implicit.feature_units(feature_set, self.force_input is not None)
            if by_reference:
                self.input_names = [v.name for v in implicit.reference]
                self.input_units = [v.unit for v in implicit.reference]
                self.reference = TorchFunction(implicit.reference_features(feature_set,
                                                                           self.force_input))
        self.residual = uses_prior(run.config.model)
        # what it outputs: forces or currents, or another machine's efforts
        self.labels = run.config.features.labels if machine is None else "efforts"
        self.prior_parameters = run.prior_parameters
        self.prior = (RigidBodyForce(feature_set, self.prior_parameters, self.labels)
                      if self.residual and prior else None)
        for name, value in (("feature_low", run.feature_scaler.low),
                            ("feature_span", run.feature_scaler.span),
                            ("label_low", run.label_scaler.low),
                            ("label_span", run.label_scaler.span)):
            self.register_buffer(name, torch.tensor(np.asarray(value), dtype=torch.float64))

    def forward(self, inputs: torch.Tensor, *state: torch.Tensor) -> tuple[torch.Tensor, ...]:
        inputs = inputs.double()
        if self.reference is not None:
            features = self.reference(inputs)[0]
        else:
            features = inputs
        scaled = (features - self.feature_low) / self.feature_span
        out, new_state = self.network(scaled.float().unsqueeze(0), tuple(state) if state else None)
        out = out.squeeze(0).double() * self.label_span
        if not self.residual:  # the low end is in the linear map where that is outside
            return (out if self.linear_map is not None else out + self.label_low, *new_state)
        out = out * trust(scaled)
        forces = out + self.prior(features) if self.prior is not None else out
        return (forces, *new_state)

    def initial_state(self) -> tuple[torch.Tensor, ...]:
        return self.network.initial_state(1, self.feature_low.device)

    def state_names(self) -> list[str]:
        return self.network.state_names()


def _si_skip(network: LinearSkip, run: Run, low_end: bool) -> tuple[np.ndarray, np.ndarray]:
    """The skip, and with `low_end` the labels' low end, as one map of SI features to SI
    outputs: weights (outputs x features) and bias, y = W x + b. A residual's targets are
    scaled by the span alone (learning.train): no low end to add."""
    weight = network.linear.weight.detach().cpu().double().numpy()
    bias = network.linear.bias.detach().cpu().double().numpy()
    low, span = np.asarray(run.feature_scaler.low), np.asarray(run.feature_scaler.span)
    label_low, label_span = np.asarray(run.label_scaler.low), np.asarray(run.label_scaler.span)
    return (label_span[:, None] * weight / span[None, :],
            label_span * (bias - weight @ (low / span)) + (label_low if low_end else 0.0))


class EnsembleSIModel(nn.Module):
    """The mean force of several SI models of one kind, trained apart (other seeds), with
    their states one after the other; it runs as one graph like a single model.

    Averaging cancels part of what each network learned from its own draw of training noise,
    initial weights and batches: on the hardware stand-in, three physics-guided networks gave
    e2 134 / 79, 79 / 74 and 74 / 88 alone, 105 / 88 averaged (learning.evaluate).
    """

    def __init__(self, members: list[SIModel]) -> None:
        super().__init__()
        first = members[0]  # the members are of one kind on one feature set (learning.export)
        self.members = nn.ModuleList(members)
        self.input_names, self.input_units = first.input_names, first.input_units
        self.residual, self.prior_parameters = first.residual, first.prior_parameters
        self.force_input = first.force_input
        self.labels = first.labels
        self.counts = [len(member.initial_state()) for member in members]
        maps = [m.linear_map for m in members]
        self.linear_map = None if any(m is None for m in maps) else (
            np.mean([m[0] for m in maps if m is not None], axis=0),
            np.mean([m[1] for m in maps if m is not None], axis=0))

    def forward(self, inputs: torch.Tensor, *state: torch.Tensor) -> tuple[torch.Tensor, ...]:
        forces, new_state, start = [], [], 0
        for member, count in zip(self.members, self.counts):
            own = state[start:start + count] if state else ()
            out = member(inputs, *own)
            forces.append(out[0])
            new_state.extend(out[1:])
            start += count
        return (torch.stack(forces).mean(dim=0), *new_state)

    def _each(self) -> list[SIModel]:
        """The members (the ModuleList holds only SIModels)."""
        return [cast(SIModel, member) for member in self.members]

    def initial_state(self) -> tuple[torch.Tensor, ...]:
        return tuple(s for member in self._each() for s in member.initial_state())

    def state_names(self) -> list[str]:
        return [f"member{i}_{name}" for i, member in enumerate(self._each())
                for name in member.state_names()]


@torch.no_grad()
def predict(run: Run, inputs: np.ndarray, kind: str = "features") -> np.ndarray:
    """Forces (T, 2) [N] for a whole sequence of SI inputs (T, n_inputs), from the zero state."""
    model = SIModel(run, kind)
    with torch_threads():
        forces: np.ndarray = model(torch.as_tensor(inputs, dtype=torch.float64),
                                   *model.initial_state())[0].numpy()
        return forces
