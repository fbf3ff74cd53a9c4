"""The closed loop without FMUs (tests/loops.py: the nominal plant's System under RK4, 1 ms
steps of four 0.25 ms sub-steps, quantized encoders, with the controller and feedforward
Systems, stepped in the co-simulation's order) against the linear design and the thesis."""

import math

import numpy as np
import pytest
from scipy import signal

from flexff.controllers.feedback import controller_design
from flexff.plant.paths import Chain, Circle, Line, sample
from flexff.plant.references import thesis_evaluation
from tests.loops import STEP, loop_systems, monolithic

SUBSTEPS = 4
COUNT = 2 * math.pi / 2048 * 0.3086  # an upper arm's travel per encoder count: 0.95 mm


@pytest.fixture(scope="module")
def simulate():
    systems = loop_systems("nominal")

    def run(reference, use_ff):
        """Tracking error e = ref - true position (2 x n) and the currents (3 x n)."""
        signals = reference.signals()
        out = monolithic(systems, signals, STEP / SUBSTEPS, use_ff,
                         {"x_start": reference.x[0], "y_start": reference.y[0]})
        error = np.vstack([signals["x_ref"] - out["x"], signals["y_ref"] - out["y"]])
        return error, np.vstack([out[n] for n in ("i1", "i2", "i3")])

    return run


def norms(error, duration):
    """The thesis's average 2-norm sqrt(sum e^2 dt) / T [m/sqrt(s)] and max |e| [m], per axis."""
    return np.sqrt(np.sum(error**2, axis=1) * STEP) / duration, np.abs(error).max(axis=1)


def sensitivity(design):
    """Discrete S = 1 / (1 + C P): reference to error of one axis of the linear design loop."""
    plant = design.plant.discretized(STEP)
    p_num, p_den = signal.ss2tf(plant.A, plant.B, plant.C, plant.D)
    c_num, c_den = signal.ss2tf(*(getattr(design.discrete, k) for k in "ABCD"))
    loop_num, loop_den = np.polymul(c_num.ravel(), p_num.ravel()), np.polymul(c_den, p_den)
    return signal.dlti(loop_den, np.polyadd(loop_den, loop_num), dt=STEP)


def test_slow_circle_follows_the_linear_design_and_feedforward_removes_the_lag(simulate):
    """0.02 m radius, one turn in 10 s after a 2 s approach.

    Below the crossover the loop gain is only about kp/k ~ 0.5 (the flexures' stiffness) until
    the integrator takes over, so PID alone lags by most of the radius. The nonlinear loop
    (allocation, kinematics, quantized encoders) must match the linear design's prediction
    e = S r within about one encoder count, and the rigid-body feedforward must bring the error
    below one count.
    """
    path = Chain((Line((0, 0), (0.02, 0), 2.0), Circle((0, 0), 0.02, 0.0, 1.0, 10.0)))
    reference = sample(path, STEP)
    error, currents = simulate(reference, use_ff=False)
    s = sensitivity(controller_design("nominal"))
    predicted = np.vstack([signal.dlsim(s, r)[1].ravel() for r in (reference.x, reference.y)])
    assert np.abs(error - predicted).max() < 1.2 * COUNT
    assert np.abs(predicted).max() > 10 * COUNT
    ff_error, ff_currents = simulate(reference, use_ff=True)
    assert np.abs(ff_error).max() < COUNT
    assert max(np.abs(currents).max(), np.abs(ff_currents).max()) < 10  # amplifier limit


def test_rigid_body_feedforward_improves_the_thesis_evaluation(simulate):
    reference = thesis_evaluation(STEP)
    pid_error, pid_currents = simulate(reference, use_ff=False)
    ff_error, ff_currents = simulate(reference, use_ff=True)
    pid_e2, pid_einf = norms(pid_error, reference.duration)
    ff_e2, ff_einf = norms(ff_error, reference.duration)
    print(f"\nthesis evaluation reference, nominal plant (x, y):\n"
          f"  PID alone: e2 = {pid_e2 * 1e4} 1e-4 m/sqrt(s), einf = {pid_einf * 1e4} 1e-4 m\n"
          f"  with rigid-body feedforward: e2 = {ff_e2 * 1e4} 1e-4 m/sqrt(s), "
          f"einf = {ff_einf * 1e4} 1e-4 m")
    # PID alone lags far behind at 0.96 Hz, well above its 2.66 Hz bandwidth's comfort zone
    assert np.all(pid_einf > 50e-4)
    # the exact inverse model leaves mostly the encoder quantization
    assert np.all(ff_e2 < pid_e2 / 10) and np.all(ff_einf < pid_einf / 10)
    assert np.all(ff_einf < COUNT)
    assert max(np.abs(pid_currents).max(), np.abs(ff_currents).max()) < 10
