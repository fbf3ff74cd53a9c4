"""learning.samples.evaluate_samples: CasADi's map in numpy's memory gives what the
Function gives sample by sample."""

import casadi as ca
import numpy as np

from flexff.controllers.features import motion_function
from flexff.learning.samples import MAP_CHUNK, evaluate_samples


def test_chunks_and_the_padded_last_one_equal_the_function_sample_by_sample():
    function = motion_function("directions")
    rng = np.random.default_rng(1)
    n = 2 * MAP_CHUNK + 17  # two whole chunks and a padded one
    pos = 0.005 * rng.standard_normal((n, 2))  # about the workspace's centre, where it moves
    vel, acc = 0.02 * rng.standard_normal((n, 2)), 0.2 * rng.standard_normal((n, 2))
    out = evaluate_samples(function, pos, vel, acc)
    assert out.shape == (n, function.size1_out(0)) and np.isfinite(out).all()
    for k in (0, MAP_CHUNK - 1, MAP_CHUNK, n - 1):
        np.testing.assert_array_equal(out[k], np.asarray(function(pos[k], vel[k], acc[k])).ravel())


def test_an_output_with_structural_zeros_comes_back_dense():
    x = ca.SX.sym("x", 2)
    y = ca.SX(3, 1)  # y[1] is a structural zero: CasADi stores only y[0] and y[2]
    y[0], y[2] = 2 * x[0], x[1] ** 2
    samples = np.arange(10.0).reshape(5, 2)
    np.testing.assert_array_equal(evaluate_samples(ca.Function("f", [x], [y]), samples),
                                  np.column_stack([2 * samples[:, 0], np.zeros(5),
                                                   samples[:, 1] ** 2]))
