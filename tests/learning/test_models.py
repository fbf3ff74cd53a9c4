"""Networks: shapes, causality, receptive field, streaming state, sizes, initialization."""

import numpy as np
import pytest
import torch

from flexff.learning.models import (
    TemporalConvNet,
    build_network,
    fit_linear_skip,
    parameter_count,
    receptive_field,
    uses_prior,
)

SMALL = {
    "lstm": {"hidden": 12, "layers": 2, "dropout": 0.05},
    "cnn-lstm": {"conv_channels": [8, 6, 4], "conv_kernels": [10, 4, 2], "hidden": 12,
                 "layers": 2, "dropout": 0.05},
    "tcn": {"channels": 10, "levels": 4, "kernel": 3, "dropout": 0.05},
    "pgnn": {"channels": 8, "levels": 3, "kernel": 3, "dropout": 0.05},
}
KINDS = list(SMALL)


pytestmark = pytest.mark.usefixtures("few_threads")


def _net(kind: str, n_features: int = 5) -> torch.nn.Module:
    torch.manual_seed(0)
    net = build_network(kind, n_features, **SMALL[kind]).double().eval()
    if uses_prior(kind):  # the zero head would hide everything below it
        torch.nn.init.normal_(net.head.weight)
    return net


@pytest.mark.parametrize("kind", KINDS)
def test_output_shape_and_state_shapes(kind):
    net = _net(kind)
    y, state = net(torch.randn(3, 40, 5, dtype=torch.float64))
    assert y.shape == (3, 40, 2)
    assert [tuple(s.shape) for s in state] == net.state_shapes(3)
    assert len(net.state_names()) == len(state)


@pytest.mark.parametrize("kind", KINDS)
def test_output_at_t_does_not_depend_on_later_inputs(kind):
    net = _net(kind)
    x = torch.randn(2, 60, 5, dtype=torch.float64)
    future = x.clone()
    future[:, 31:] += torch.randn_like(future[:, 31:]) * 3
    y, _ = net(x)
    y_future, _ = net(future)
    torch.testing.assert_close(y[:, :31], y_future[:, :31], rtol=0, atol=0)
    assert (y[:, 31:] - y_future[:, 31:]).abs().max() > 1e-6  # and the later ones do change


@pytest.mark.parametrize("kind", KINDS)
def test_chunks_with_carried_state_equal_the_whole_sequence(kind):
    net = _net(kind)
    x = torch.randn(2, 50, 5, dtype=torch.float64)
    whole, _ = net(x)
    state, parts = None, []
    for start in (0, 1, 17, 18, 40):  # uneven chunks, single steps included
        stop = {0: 1, 1: 17, 17: 18, 18: 40, 40: 50}[start]
        y, state = net(x[:, start:stop], state)
        parts.append(y)
    torch.testing.assert_close(torch.cat(parts, dim=1), whole, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kind,skip", [("tcn", False), ("tcn", True), ("pgnn", False)])
def test_the_streaming_tcn_gives_the_tcns_outputs_from_the_start(kind, skip):
    torch.manual_seed(1)
    net = build_network(kind, 5, linear_skip=skip, **SMALL[kind]).double().eval()
    for parameter in net.parameters():  # nonzero biases: zero input is not at rest at zero
        torch.nn.init.normal_(parameter, std=0.5)
    stepped = net.step_form()
    assert type(stepped).__name__ == ("LinearSkip" if skip else "StreamingTCN")
    assert stepped.state_names()[0] == "level0_buffer" and len(stepped.state_names()) == \
        SMALL[kind]["levels"]
    x = torch.randn(2, 50, 5, dtype=torch.float64)
    whole, _ = net(x)
    state, steps = None, []
    for t in range(50):
        y, state = stepped(x[:, t:t + 1], state)
        steps.append(y)
    torch.testing.assert_close(stepped(x)[0], whole, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(torch.cat(steps, dim=1), whole, rtol=1e-12, atol=1e-12)
    assert [tuple(s.shape) for s in state] == stepped.state_shapes(2)


def test_a_network_without_a_cheaper_step_form_is_its_own():
    for skip in (False, True):
        net = build_network("lstm", 5, linear_skip=skip, **SMALL["lstm"])
        assert net.step_form() is net


@pytest.mark.parametrize("levels,kernel", [(6, 3), (4, 2), (3, 5)])
def test_tcn_receptive_field_equals_the_formula(levels, kernel):
    net = TemporalConvNet(3, channels=6, levels=levels, kernel=kernel, dropout=0.0).double().eval()
    for param in net.parameters():  # positive weights and inputs: no ReLU hides a path
        torch.nn.init.uniform_(param, 0.1, 1.0)
    expected = 1 + (kernel - 1) * (2 ** levels - 1)
    dilations = [2 ** i for i in range(levels)]
    assert net.receptive_field == expected == receptive_field(kernel, dilations)
    length = expected + 20
    x = torch.rand(1, length, 3, dtype=torch.float64, requires_grad=True)
    y, _ = net(x)
    y[0, -1].sum().backward()
    reached = (x.grad[0].abs().sum(dim=1) > 0).nonzero().flatten()
    assert int(reached.min()) == length - expected and int(reached.max()) == length - 1


def test_thesis_tcn_sees_127_samples_where_eq_3_4_says_128():
    assert TemporalConvNet(63, channels=200, levels=6, kernel=3).receptive_field == 127
    assert 2 ** 6 * (3 - 1) == 128


def test_parameter_counts_of_the_thesis_sizes():
    lstm = build_network("lstm", 63, hidden=100, layers=2, dropout=0.05)
    # PyTorch keeps two bias vectors per LSTM layer (Keras one): 4*100*(63+100+2), 4*100*202
    assert parameter_count(lstm) == 4 * 100 * 165 + 4 * 100 * 202 + 202
    tcn = build_network("tcn", 63, channels=200, levels=6, kernel=3, dropout=0.05)
    convs = (63 * 3 + 1) * 200 + 5 * (200 * 3 + 1) * 200
    assert parameter_count(tcn) == convs + (63 + 1) * 200 + 402  # plus 1x1 residual, head
    cnn = build_network("cnn-lstm", 63, conv_channels=[40, 16, 4], conv_kernels=[10, 4, 2],
                        hidden=100, layers=2, dropout=0.05)
    assert parameter_count(cnn) == (63 * 10 + 1) * 40 + (40 * 4 + 1) * 16 + (16 * 2 + 1) * 4 + \
        4 * 100 * 106 + 4 * 100 * 202 + 202


def test_initialization_follows_keras():
    torch.manual_seed(2)
    net = build_network("lstm", 63, hidden=100, layers=1, dropout=0.0)
    bias = net.lstm.bias_ih_l0.detach()
    assert torch.all(bias[100:200] == 1) and torch.all(bias[:100] == 0)
    recurrent = net.lstm.weight_hh_l0.detach()[:100]
    torch.testing.assert_close(recurrent @ recurrent.T, torch.eye(100), atol=1e-5, rtol=0)
    bound = (6 / (63 + 400)) ** 0.5  # Glorot-uniform limit of the stacked input kernel
    assert net.lstm.weight_ih_l0.abs().max() <= bound


def test_pgnn_starts_as_the_rigid_body_model():
    net = build_network("pgnn", 6, channels=8, levels=2, kernel=3, dropout=0.0).eval()
    y, _ = net(torch.randn(1, 20, 6))
    assert torch.all(y == 0)


def test_unknown_model_and_bad_sizes_are_refused():
    with pytest.raises(ValueError, match=r"unknown model 'gru'.*lstm, cnn-lstm, tcn, pgnn"):
        build_network("gru", 6)
    with pytest.raises(ValueError, match="levels"):
        build_network("tcn", 6, levels=0)


@pytest.mark.parametrize("kind", ["lstm", "cnn-lstm", "tcn"])
def test_a_fitted_linear_skip_starts_as_the_least_squares_fit(kind):
    """After fit_linear_skip the network's output is numpy's least-squares solution of the
    same samples (its head zeroed), and the state is the inner network's."""
    torch.manual_seed(0)
    net = build_network(kind, 5, linear_skip=True, **SMALL[kind]).double().eval()
    x = torch.randn(2, 40, 5, dtype=torch.float64)
    y = x @ torch.randn(5, 2, dtype=torch.float64) + 0.1 * torch.randn(2, 40, 2,
                                                                         dtype=torch.float64)
    fit_linear_skip(net, x.reshape(-1, 5), y.reshape(-1, 2))
    design = np.column_stack([x.reshape(-1, 5).numpy(), np.ones(80)])
    expected = design @ np.linalg.lstsq(design, y.reshape(-1, 2).numpy(), rcond=None)[0]
    out, state = net(x)
    np.testing.assert_allclose(out.reshape(-1, 2).detach().numpy(), expected, atol=1e-10)
    assert net.state_names() == net.network.state_names()
    assert [tuple(s.shape) for s in state] == net.state_shapes(2)


def test_a_residual_that_does_not_help_its_output_is_silenced():
    """A residual net's output whose validation error its skip does not lower below the
    prior's (the zero residual: its target is noise on the training samples, zero on the
    validation ones) is set to zero for any input; the
    output whose residual is linear in the features keeps its fit."""
    from flexff.learning.batches import TRAIN, VALIDATION, SequenceSet
    from flexff.learning.models import silence_outputs
    from flexff.learning.train import unhelpful_residuals

    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    net = build_network("pgnn", 5, linear_skip=True, **SMALL["pgnn"]).eval()
    x = rng.standard_normal((4, 60, 5))
    roles = [np.where(np.arange(60) < 40, TRAIN, VALIDATION) for _ in range(4)]
    noise = np.where(np.arange(60) < 40, 0.1 * rng.standard_normal((4, 60)), 0.0)
    y = np.stack([x @ rng.standard_normal(5), noise], axis=-1)  # the second: none to learn
    data = SequenceSet.build(list(x), list(y), roles, torch.device("cpu"))
    fitted = data.role == TRAIN
    fit_linear_skip(net, data.x[fitted], data.y[fitted])
    assert unhelpful_residuals(net, data) == [1]
    silence_outputs(net, [1])
    out, _ = net(torch.randn(2, 30, 5))
    assert torch.all(out[..., 1] == 0) and torch.any(out[..., 0] != 0)
    assert unhelpful_residuals(net, data) == [1]  # zero: no lower than the prior, kept so
