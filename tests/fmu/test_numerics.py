"""Numbers produced by generated FMUs, against independent references.

- continuous: Python RK4 on the same CasADi functions with the same sub-steps (to 1e-12), and
  scipy's DOP853 at rtol = atol = 1e-12 on a numpy right-hand side written separately (to 1e-8);
- discrete: the PI recurrence written in Python;
- noise: the generator re-implemented in Python, plus sample statistics.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests.fmu_toys import (
    DUFFING_PARAMS,
    LoggedSlave,
    duffing,
    normals,
    rk4_reference,
)
from tests.runners import run_fmu

H = 1e-3
STEPS = 1000
FORCE = 2.0 * np.sin(30.0 * H * np.arange(STEPS)) + 0.5


def states(run):
    return np.column_stack([run["q"], run["v"]])


@pytest.mark.parametrize("force", [np.zeros(STEPS), FORCE], ids=["free", "driven"])
def test_matches_python_rk4(duffing_fmu, force):
    run = run_fmu(duffing_fmu, STEPS, H, inputs={"F": force}, record=["q", "v"])
    ref = rk4_reference(duffing(), {}, force, [(H, 4)] * STEPS)  # max_substep 2.5e-4 -> 4
    assert np.abs(states(run) - ref).max() <= 1e-12
    assert np.abs(ref[:, 0]).max() > 0.01  # it really moved


@pytest.mark.parametrize("max_substep, substeps", [(1e-2, 1), (2.5e-3, 4), (3e-3, 4), (4e-3, 3),
                                                   (1.1e-2, 1)])
def test_substep_count(duffing_fmu, max_substep, substeps):
    """n = ceil(h / max_substep - 1e-12): an exact multiple does not add a sub-step."""
    h = 1e-2  # coarse, so that one sub-step more or less is clearly visible
    run = run_fmu(duffing_fmu, 50, h, inputs={"F": FORCE[:50]},
                  parameters={"max_substep": max_substep}, record=["q", "v"])
    ref = rk4_reference(duffing(), {}, FORCE[:50], [(h, substeps)] * 50)
    other = rk4_reference(duffing(), {}, FORCE[:50], [(h, substeps + 1)] * 50)
    assert np.abs(states(run) - ref).max() <= 1e-12
    assert np.abs(states(run) - other).max() > 1e-8  # far above the 1e-12 of a match


def test_variable_step_sizes(duffing_fmu):
    sizes = [1e-3, 5e-4, 2e-3, 7e-4, 1e-4] * 40
    s = LoggedSlave(duffing_fmu)
    s.initialize()
    t, xs = 0.0, [s.get("q", "v")]
    for h, f in zip(sizes, FORCE[:len(sizes)], strict=True):
        s.set(F=f)
        s.slave.doStep(t, h)
        t += h
        xs.append(s.get("q", "v"))
    s.free()
    plan = [(h, max(1, int(np.ceil(h / 2.5e-4 - 1e-12)))) for h in sizes]
    ref = rk4_reference(duffing(), {}, FORCE[:len(sizes)], plan)
    assert np.abs(np.array(xs) - ref).max() <= 1e-12


def duffing_rhs(p):
    """The Duffing dynamics written again in numpy, independent of the CasADi model."""
    def rhs(t, x, force):
        q, v = x
        return [v, (force - p["c"] * v - p["k"] * q - p["alpha"] * q**3) / p["m"]]
    return rhs


@pytest.mark.parametrize("force", [np.zeros(STEPS), FORCE], ids=["free", "driven"])
def test_matches_dop853(duffing_fmu, force):
    p = {**DUFFING_PARAMS, "c": 0.8, "q0": 0.04, "v0": -0.3}
    run = run_fmu(duffing_fmu, STEPS, H, inputs={"F": force},
                  parameters={"c": p["c"], "q0": p["q0"], "v0": p["v0"], "max_substep": 1e-4},
                  record=["q", "v"])
    rhs = duffing_rhs(p)
    x = np.array([p["q0"], p["v0"]])
    ref = [x]
    for k, f in enumerate(force):  # inputs are held over each step: integrate step by step
        sol = solve_ivp(rhs, (k * H, (k + 1) * H), x, method="DOP853", rtol=1e-12, atol=1e-12,
                        args=(f,))
        x = sol.y[:, -1]
        ref.append(x)
    assert np.abs(states(run) - np.array(ref)).max() <= 1e-8


def test_outputs_and_direct_feedthrough(duffing_fmu):
    """Outputs are evaluated at fmi2GetReal time from the current state and inputs."""
    p = DUFFING_PARAMS
    s = LoggedSlave(duffing_fmu)
    s.initialize()
    for k in range(20):
        s.set(F=FORCE[k])
        s.slave.doStep(k * H, H)
    q, v = s.get("q", "v")
    for force in (0.0, 3.0, -7.5):
        s.set(F=force)
        q_true, v_true, a = s.get("q_true", "v_true", "a")
        assert (q_true, v_true) == (q, v)
        assert a == pytest.approx((force - p["c"] * v - p["k"] * q - p["alpha"] * q**3) / p["m"],
                                  rel=1e-14)
    s.free()


def test_parameter_change_takes_effect_at_next_step(duffing_fmu):
    s = LoggedSlave(duffing_fmu)
    s.initialize()
    xs = [s.get("q", "v")]
    for k in range(200):
        if k == 100:
            s.set(k=350.0)
        s.set(F=FORCE[k])
        s.slave.doStep(k * H, H)
        xs.append(s.get("q", "v"))
    s.free()
    first = rk4_reference(duffing(), {}, FORCE[:100], [(H, 4)] * 100)
    second = rk4_reference(duffing(q0=first[-1, 0], v0=first[-1, 1]), {"k": 350.0},
                           FORCE[100:200], [(H, 4)] * 100)
    assert np.abs(np.array(xs) - np.vstack([first, second[1:]])).max() <= 1e-12


@pytest.mark.parametrize("seed", [0, 7, -3])
def test_noise_is_the_documented_generator(duffing_fmu, seed):
    """w_k: one standard normal per step of xoshiro256** seeded by splitmix64(seed)."""
    run = run_fmu(duffing_fmu, 300, H, parameters={"seed": seed, "sigma": 0.01},
                  record=["q_meas", "q_true"])
    w = np.array(normals(seed, 301))
    assert np.abs(run["q_meas"] - (run["q_true"] + 0.01 * w)).max() <= 1e-15


def test_noise_statistics_and_seeds(duffing_fmu):
    runs = [run_fmu(duffing_fmu, 20000, H, parameters={"seed": seed, "sigma": 1.0, "q0": 0.0},
                    record=["q_meas", "q_true"]) for seed in (1, 2)]
    w1, w2 = (r["q_meas"] - r["q_true"] for r in runs)
    assert abs(w1.mean()) < 0.03 and abs(w1.std() - 1.0) < 0.02
    assert abs(np.corrcoef(w1[:-1], w1[1:])[0, 1]) < 0.03  # white
    assert abs(np.corrcoef(w1, w2)[0, 1]) < 0.03  # seeds give independent streams


def test_discrete_pi_matches_recurrence(pi_fmu):
    rng = np.random.default_rng(0)
    r = rng.uniform(-0.01, 0.01, 500)
    y = rng.uniform(-0.01, 0.01, 500)
    kp, ki, umax = 80.0, 900.0, 0.5
    run = run_fmu(pi_fmu, 500, 1e-3, inputs={"r": r, "y": y},
                  parameters={"kp": kp, "ki": ki, "umax": umax}, record=["u", "I"])
    integral, u_ref, i_ref = 0.0, [], []
    for e in r - y:
        i_ref.append(integral)
        u_ref.append(min(max(kp * e + ki * integral, -umax), umax))
        integral = integral + 1e-3 * e
    assert np.array_equal(run["I"][:-1], i_ref) and run["I"][-1] == integral
    assert np.abs(run["u"][:-1] - u_ref).max() <= 1e-12
    assert np.abs(u_ref).max() == umax  # the saturation was exercised
