"""CasADi expressions replayed in torch equal CasADi itself; the pgnn prior is eq. (2.4)."""

import casadi as ca
import numpy as np
import pytest
import torch

from flexff.controllers.features import motion_features, motion_function
from flexff.learning.casadi_torch import TorchFunction, atan2, frozen
from flexff.learning.rigid import RigidBodyForce, rigid_forces

pytestmark = pytest.mark.usefixtures("few_threads")


def _samples(n=200, seed=0):
    rng = np.random.default_rng(seed)
    radius = 0.05 * np.sqrt(rng.uniform(0, 1, n))
    angle = rng.uniform(-np.pi, np.pi, n)
    pos = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    return pos, rng.normal(0, 0.3, (n, 2)), rng.normal(0, 3.0, (n, 2))


def test_inverse_dynamics_in_torch_equals_casadi(nominal):
    pos, vel, acc = _samples()
    p = nominal.parameter_values()
    expected = np.asarray(nominal.inverse_dynamics.map(len(pos))(pos.T, vel.T, acc.T, p)).T
    feats = motion_features(pos, vel, acc, "compact")
    np.testing.assert_allclose(rigid_forces(feats, "compact"), expected, rtol=1e-12, atol=1e-12)
    torch_forces = RigidBodyForce("compact")(torch.as_tensor(feats)).numpy()
    np.testing.assert_allclose(torch_forces, expected, rtol=1e-12, atol=1e-12)
    full = motion_features(pos, vel, acc, "full")
    np.testing.assert_allclose(RigidBodyForce("full")(torch.as_tensor(full)).numpy(), expected,
                               rtol=1e-12, atol=1e-12)


def test_features_in_torch_equal_casadi():
    pos, vel, acc = _samples(seed=1)
    function = TorchFunction(motion_function("full"))
    out = function(*(torch.as_tensor(a) for a in (pos, vel, acc)))[0].numpy()
    np.testing.assert_allclose(out, motion_features(pos, vel, acc, "full"), rtol=1e-12,
                               atol=1e-12)


def test_float64_atan2_is_exact_in_every_quadrant():
    rng = np.random.default_rng(2)
    y, x = (torch.as_tensor(rng.normal(0, 1, 10000)) for _ in range(2))
    torch.testing.assert_close(atan2(y, x), torch.atan2(y, x), rtol=0, atol=1e-15)
    tiny = torch.tensor([1e-9, -1e-9, 2.0], dtype=torch.float64)
    torch.testing.assert_close(atan2(tiny, torch.tensor([-1.0, -1.0, 1e-12], dtype=torch.float64)),
                               torch.atan2(tiny, torch.tensor([-1.0, -1.0, 1e-12],
                                                              dtype=torch.float64)))


def test_broadcasting_constants_and_frozen_inputs():
    x, k = ca.SX.sym("x", 2), ca.SX.sym("k")
    f = ca.Function("f", [x, k], [ca.vertcat(k * ca.sin(x[0]) + ca.fmax(x[1], 0.5), 3.0)])
    g = frozen(f, [1], [2.0])
    assert g.n_in() == 1
    values = torch.tensor([[0.3, 0.1], [1.0, 0.9]], dtype=torch.float64)
    out = TorchFunction(g)(values)[0]
    expected = np.asarray(g.map(2)(values.numpy().T)).T
    np.testing.assert_allclose(out.numpy(), expected)
    assert out.shape == (2, 2)


def test_unsupported_operations_and_shapes_are_refused():
    x = ca.SX.sym("x")
    with pytest.raises(NotImplementedError, match="OP_ERF"):
        TorchFunction(ca.Function("f", [x], [ca.erf(x)]))
    m = ca.SX.sym("m", 2, 2)
    with pytest.raises(ValueError, match="dense column vector"):
        TorchFunction(ca.Function("g", [m], [ca.trace(m)]))
