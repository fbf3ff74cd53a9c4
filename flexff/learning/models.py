"""The networks: LSTM, CNN-LSTM and TCN as in the thesis, and the residual net of the pgnn.

Every network maps scaled features (batch, time, n_features) to scaled outputs and is causal.
Each takes and returns an explicit state (LSTM (h, c); TCN an input buffer; CNN-LSTM both),
so one forward serves truncated backpropagation, whole sequences and the step form exported
to ONNX. Causal padding is done once, at the input (`CausalHistory`). A TCN of kernel k and L
levels sees R = 1 + (k - 1) (2^L - 1) samples; the thesis's eq. (3.4) counts one more.
Initialization follows Keras's defaults.

Docs: "Learning", section The models (docs/explanation/learning.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from flexff.fmu.errors import InputError
from flexff.learning.rest_anchor import REST_SAMPLES, RestAnchor, fit_through

State = tuple[torch.Tensor, ...]
N_OUTPUTS = 2  # the forces Fx, Fy; a current-level model has 3


class SequenceNetwork(nn.Module):
    """Base class: causal sequence network with explicit state."""

    history: int = 0  # past input samples kept in the state (0: none)

    def initial_state(self, batch: int, device: torch.device | str = "cpu",
                      dtype: torch.dtype = torch.float32) -> State:
        """The zero state every sequence starts from."""
        return tuple(torch.zeros(shape, device=device, dtype=dtype)
                     for shape in self.state_shapes(batch))

    def _zero_state(self, x: torch.Tensor) -> State:
        return self.initial_state(x.shape[0], x.device, x.dtype)

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        raise NotImplementedError

    def state_names(self) -> list[str]:
        raise NotImplementedError

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        raise NotImplementedError

    def step_form(self) -> SequenceNetwork:
        """The same function arranged for one sample per call, as the ONNX export runs it:
        the network itself unless a subclass has a cheaper arrangement."""
        return self


class CausalHistory(nn.Module):
    """The causal pad: prepends the last `length` inputs (zeros at first) to a chunk.

    Input (batch, channels, time) and a buffer (batch, channels, length); returns the padded
    input (batch, channels, length + time) and the new buffer, its last `length` samples.
    """

    def __init__(self, length: int) -> None:
        super().__init__()
        self.length = length

    def forward(self, x: torch.Tensor, buffer: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        padded = torch.cat([buffer, x], dim=2)
        return padded, padded[:, :, -self.length:]


class TemporalBlock(nn.Module):
    """One TCN level: dilated causal convolution, ReLU, dropout, plus a residual connection.

    Unpadded: the output is (kernel - 1) * dilation samples shorter than the input, and the
    residual is cropped to match (a 1x1 convolution when the channel count changes).
    """

    def __init__(self, n_in: int, n_out: int, kernel: int, dilation: int, dropout: float) -> None:
        super().__init__()
        self.conv = nn.Conv1d(n_in, n_out, kernel, dilation=dilation)
        self.dropout = nn.Dropout(dropout)
        self.residual = nn.Conv1d(n_in, n_out, 1) if n_in != n_out else nn.Identity()
        self.shrink = (kernel - 1) * dilation

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.dropout(torch.relu(self.conv(x)))
        return torch.relu(out + self.residual(x[:, :, self.shrink:]))


class TemporalConvNet(SequenceNetwork):
    """TCN (Bai et al., locuslab style): `levels` temporal blocks, dilations 1, 2, 4, ...,
    `channels` filters each, then a linear head per time step."""

    def __init__(self, n_features: int, channels: int = 200, levels: int = 6, kernel: int = 3,
                 dropout: float = 0.05, n_outputs: int = N_OUTPUTS) -> None:
        super().__init__()
        if levels < 1 or kernel < 2:
            raise InputError(f"a TCN needs levels >= 1 and kernel >= 2, got {levels}, {kernel}")
        dilations = [2 ** i for i in range(levels)]
        self.receptive_field = receptive_field(kernel, dilations)
        self.history = self.receptive_field - 1
        self.n_features = n_features
        self.pad = CausalHistory(self.history)
        self.blocks = nn.Sequential(*[
            TemporalBlock(n_features if i == 0 else channels, channels, kernel, d, dropout)
            for i, d in enumerate(dilations)])
        self.head = nn.Linear(channels, n_outputs)
        glorot_init(self)

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        return [(batch, self.n_features, self.history)]

    def state_names(self) -> list[str]:
        return ["input_buffer"]

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        (buffer,) = state if state is not None else self._zero_state(x)
        padded, buffer = self.pad(x.transpose(1, 2), buffer)
        hidden = self.blocks(padded).transpose(1, 2)
        return self.head(hidden), (buffer,)

    def step_form(self) -> StreamingTCN:
        return StreamingTCN(self)


class StreamingTCN(SequenceNetwork):
    """A trained TCN arranged for one sample per call: each level keeps the last
    (kernel - 1) * dilation samples of its own input, so a new sample costs one output per
    level instead of recomputing the receptive field (4 outputs against 72 for 4 levels of
    kernel 3).

    It gives the TCN's outputs from the TCN's zero state: before the start, the TCN sees zero
    input, on which every level's output is a constant per channel (`rest`). The buffers hold
    their level's input minus that constant, so that they too start at zero.
    """

    def __init__(self, tcn: TemporalConvNet) -> None:
        super().__init__()
        self.history = tcn.history
        self.blocks, self.head = tcn.blocks, tcn.head
        self.lengths = [block.shrink for block in _levels(tcn)]
        weight = tcn.head.weight
        level_input = torch.zeros(1, tcn.n_features, 1, dtype=weight.dtype, device=weight.device)
        with torch.no_grad():
            for i, block in enumerate(_levels(tcn)):
                self.register_buffer(f"rest{i}", level_input.clone())
                level_input = block(level_input.expand(-1, -1, block.shrink + 1))

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        return [(batch, getattr(self, f"rest{i}").shape[1], length)
                for i, length in enumerate(self.lengths)]

    def state_names(self) -> list[str]:
        return [f"level{i}_buffer" for i in range(len(self.lengths))]

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        buffers = state if state is not None else self._zero_state(x)
        hidden, new_state = x.transpose(1, 2), []
        for i, (block, buffer) in enumerate(zip(self.blocks, buffers)):
            rest = getattr(self, f"rest{i}")
            padded = torch.cat([buffer + rest, hidden], dim=2)
            new_state.append(padded[:, :, -self.lengths[i]:] - rest)
            hidden = block(padded)
        return self.head(hidden.transpose(1, 2)), tuple(new_state)


def _levels(tcn: TemporalConvNet) -> list[TemporalBlock]:
    """The temporal blocks of a TCN, in order."""
    return [block for block in tcn.blocks if isinstance(block, TemporalBlock)]


class LSTMNet(SequenceNetwork):
    """Stacked LSTM, dropout, linear head (the thesis's 2 x 100 network)."""

    def __init__(self, n_features: int, hidden: int = 100, layers: int = 2,
                 dropout: float = 0.05, n_outputs: int = N_OUTPUTS) -> None:
        super().__init__()
        self.hidden, self.layers = hidden, layers
        self.lstm = nn.LSTM(n_features, hidden, layers, batch_first=True,
                            dropout=dropout if layers > 1 else 0.0)
        self.dropout = nn.Dropout(dropout)
        self.head = nn.Linear(hidden, n_outputs)
        glorot_init(self)

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        return [(self.layers, batch, self.hidden)] * 2

    def state_names(self) -> list[str]:
        return ["h", "c"]

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        h, c = state if state is not None else self._zero_state(x)
        out, (h, c) = self.lstm(x, (h, c))
        return self.head(self.dropout(out)), (h, c)


class CNNLSTM(SequenceNetwork):
    """Causal 1-D convolutions (ReLU between them) extracting a few features for an LSTM."""

    def __init__(self, n_features: int, conv_channels: Sequence[int] = (40, 16, 4),
                 conv_kernels: Sequence[int] = (10, 4, 2), hidden: int = 100, layers: int = 2,
                 dropout: float = 0.05, n_outputs: int = N_OUTPUTS) -> None:
        super().__init__()
        if len(conv_channels) != len(conv_kernels) or not conv_channels or min(conv_kernels) < 1:
            raise InputError("conv_channels and conv_kernels must be non-empty and of equal length")
        if sum(k - 1 for k in conv_kernels) < 1:
            raise InputError("the convolutions must span more than one sample (some kernel > 1)")
        self.n_features = n_features
        self.history = sum(k - 1 for k in conv_kernels)
        self.pad = CausalHistory(self.history)
        convs: list[nn.Module] = []
        for i, (n_out, k) in enumerate(zip(conv_channels, conv_kernels)):
            if i:
                convs.append(nn.ReLU())
            convs.append(nn.Conv1d(n_features if i == 0 else conv_channels[i - 1], n_out, k))
        self.convs = nn.Sequential(*convs)
        self.lstm = LSTMNet(conv_channels[-1], hidden, layers, dropout, n_outputs)
        glorot_init(self)

    @property
    def head(self) -> nn.Linear:
        """The output layer: the LSTM's."""
        return self.lstm.head

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        return [(batch, self.n_features, self.history), *self.lstm.state_shapes(batch)]

    def state_names(self) -> list[str]:
        return ["input_buffer", *self.lstm.state_names()]

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        buffer, h, c = state if state is not None else self._zero_state(x)
        padded, buffer = self.pad(x.transpose(1, 2), buffer)
        y, (h, c) = self.lstm(self.convs(padded).transpose(1, 2), (h, c))
        return y, (buffer, h, c)


class LinearSkip(SequenceNetwork):
    """Any sequence network plus a linear map from the current input to the output.

    The inverse dynamics of the full feature set is close to linear in it (on the sim set a
    least-squares fit alone reaches a test MSE of 1.95e-8, below the rigid-body model's
    3.5e-8), but the features are nearly collinear and gradient descent does not find that
    fit in minutes. The skip, fitted by least squares before training (`fit_linear_skip`),
    starts the network where a linear model ends, and the network, its head zeroed, learns
    only what is not linear. The state is the inner network's.
    """

    def __init__(self, network: SequenceNetwork, n_features: int) -> None:
        super().__init__()
        self.network = network
        self.history = network.history
        # float64: the least-squares weights of nearly collinear features are large and
        # cancel; in float32 the sum lost 4e-5 of the force
        self.linear = nn.Linear(n_features, _head(network).out_features, dtype=torch.float64)

    def state_shapes(self, batch: int) -> list[tuple[int, ...]]:
        return self.network.state_shapes(batch)

    def state_names(self) -> list[str]:
        return self.network.state_names()

    def forward(self, x: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        y, state = self.network(x, state)
        return y + self.linear(x.double()).to(y.dtype), state

    def step_form(self) -> SequenceNetwork:
        inner = self.network.step_form()
        if inner is self.network:
            return self
        skip = LinearSkip(inner, self.linear.in_features)
        skip.linear = self.linear
        return skip


def fit_linear_skip(network: SequenceNetwork, x: torch.Tensor, y: torch.Tensor,
                    columns: slice = slice(None), anchor: RestAnchor | None = None) -> None:
    """Set the skip of a LinearSkip network to the least-squares fit y ~ x W + b over the
    samples (n, n_features), (n, n_outputs), on the features `columns` alone (the others'
    weights zero), its pinned outputs through their `anchor` (learning.rest_anchor), and
    zero the inner network's head, so that training starts from the linear fit.

    The fit is solved on the CPU whatever device the samples and the network are on: the
    nearly collinear features need the SVD-based driver (gelsd), which CUDA lacks."""
    if not isinstance(network, LinearSkip):
        return
    x, y = x.detach().cpu().double()[:, columns], y.detach().cpu().double()
    solution = fit_through(x, y, anchor, columns)
    weight = torch.zeros(network.linear.weight.shape, dtype=torch.float64)
    weight[:, columns] = solution[:-1].T
    with torch.no_grad():
        network.linear.weight.copy_(weight)  # onto the network's device
        network.linear.bias.copy_(solution[-1])
        head = _head(network.network)
        nn.init.zeros_(head.weight)
        nn.init.zeros_(head.bias)


def silence_outputs(network: SequenceNetwork, outputs: Sequence[int]) -> None:
    """Set `outputs` of a network with a linear head (and skip) to zero whatever its input:
    a residual there leaves the prior alone."""
    heads = [_head(network.network if isinstance(network, LinearSkip) else network)]
    if isinstance(network, LinearSkip):
        heads.append(network.linear)
    with torch.no_grad():
        for head in heads:
            for k in outputs:
                head.weight[k].zero_()
                head.bias[k].zero_()


# kind -> (class, whether its target is the residual over the rigid-body prior)
NETWORKS: dict[str, tuple[type[SequenceNetwork], bool]] = {
    "lstm": (LSTMNet, False),
    "cnn-lstm": (CNNLSTM, False),
    "tcn": (TemporalConvNet, False),
    "pgnn": (TemporalConvNet, True),
}
RECURRENT = ("lstm", "cnn-lstm")


def check_kind(kind: str) -> None:
    """Raise InputError naming the known model kinds if `kind` is not one."""
    if kind not in NETWORKS:
        raise InputError(f"unknown model {kind!r}: choose one of {', '.join(NETWORKS)}")


def build_network(kind: str, n_features: int, linear_skip: bool = False,
                  n_outputs: int = N_OUTPUTS, **architecture: Any) -> SequenceNetwork:
    """A fresh network of `kind` ('lstm', 'cnn-lstm', 'tcn', 'pgnn') for n_features inputs
    and n_outputs outputs, wrapped in a LinearSkip when `linear_skip`."""
    check_kind(kind)
    cls, prior = NETWORKS[kind]
    network = cls(n_features, n_outputs=n_outputs, **architecture)
    if prior:  # a zero head: training starts from the rigid-body model itself
        nn.init.zeros_(_head(network).weight)
    return LinearSkip(network, n_features) if linear_skip else network


@torch.no_grad()
def pin_at_rest(network: SequenceNetwork, anchor: RestAnchor | None) -> None:
    """Hold a trained network to its anchor (learning.rest_anchor): a linear skip's bias set
    so that the skip gives each pinned output's zero effort at zero features, and the head's
    bias of the network inside so that, having rested at the origin (REST_SAMPLES model
    samples), it adds nothing there; a network without a skip held to zero effort at rest at
    the origin on its still outputs."""
    if anchor is None:
        return
    network.eval()
    target = torch.as_tensor(anchor.outputs)
    inner, pinned = network, anchor.still
    if isinstance(network, LinearSkip):
        skip = network.linear
        given = skip(torch.as_tensor(anchor.zero, dtype=skip.weight.dtype,
                                     device=skip.weight.device)).cpu()
        for k in anchor.pinned:
            skip.bias[k] += float(target[k] - given[k])
        inner, target, pinned = network.network, torch.zeros_like(target), anchor.pinned
    head = _head(inner)
    x = torch.as_tensor(anchor.resting, dtype=head.weight.dtype, device=head.weight.device)
    out, _ = inner(x.expand(1, REST_SAMPLES, -1))
    for k in pinned:
        head.bias[k] += float(target[k] - out[0, -1, k])


def _head(network: SequenceNetwork) -> nn.Linear:
    """The output layer of a network that has one (LinearSkip has none)."""
    head = network.head
    if not isinstance(head, nn.Linear):
        raise TypeError(f"{type(network).__name__} has no linear output layer")
    return head


def uses_prior(kind: str) -> bool:
    """Whether the network learns only the residual over the rigid-body prior (the pgnn)."""
    check_kind(kind)
    return NETWORKS[kind][1]


def receptive_field(kernel: int, dilations: Sequence[int]) -> int:
    """Input samples one output of a stack of unpadded dilated convolutions depends on."""
    return 1 + (kernel - 1) * sum(dilations)


def parameter_count(network: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in network.parameters() if p.requires_grad)


def glorot_init(module: nn.Module) -> None:
    """Keras defaults: Glorot-uniform kernels, orthogonal recurrent kernels, zero biases,
    forget-gate bias 1 (PyTorch's LSTM has two bias vectors; the first carries it)."""
    for sub in module.modules():
        if isinstance(sub, (nn.Conv1d, nn.Linear)):
            nn.init.xavier_uniform_(sub.weight)
            if sub.bias is not None:
                nn.init.zeros_(sub.bias)
        elif isinstance(sub, nn.LSTM):
            for name, param in sub.named_parameters():
                if name.startswith("weight_ih"):
                    nn.init.xavier_uniform_(param)
                elif name.startswith("weight_hh"):
                    for gate in param.data.chunk(4, dim=0):
                        nn.init.orthogonal_(gate)
                else:
                    nn.init.zeros_(param)
                    if name.startswith("bias_ih"):
                        param.data[sub.hidden_size:2 * sub.hidden_size] = 1.0
