"""Any machine's model-based feedforward FMU: named by the description, validated, and run by
FMPy with the efforts of the inverse model along the reference."""

import casadi as ca
import fmpy
import numpy as np
import pytest

from flexff.controllers.machine_feedforward import inverse_model_system
from flexff.cosim.machine import parse_machine
from flexff.fmu.build import build_fmu
from flexff.fmu.errors import InputError
from flexff.fmu.validation import validate_fmu

MASS, DAMPING = np.array([2.0, 0.7]), np.array([20.0, 3.0])


def stage():
    return parse_machine({"axis": [
        {"name": n, "unit": u, "effort_unit": e, "measured": f"p.{n}",
         "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u", "range": [-0.1, 0.1],
         "velocity": 0.5, "acceleration": 5.0}
        for n, u, e in (("x", "m", "N"), ("q", "rad", "N*m"))]}, "stage.toml")


def inverse():
    pos, vel, acc = (ca.SX.sym(n, 2) for n in ("pos", "vel", "acc"))
    return ca.Function("inverse", [pos, vel, acc],
                       [ca.DM(MASS) * acc + ca.DM(DAMPING) * vel + 0.1 * ca.sin(pos)])


def test_the_fmu_gives_the_inverse_model_along_the_reference(tmp_path):
    fmu = build_fmu(inverse_model_system(stage(), inverse(), 1e-3, "a test model"),
                    tmp_path / "ff.fmu")
    assert validate_fmu(fmu) == []
    description = fmpy.read_model_description(str(fmu))
    variables = {v.name: v for v in description.modelVariables}
    assert [v.name for v in description.modelVariables if v.causality == "output"] == [
        "x_ff", "q_ff"]
    assert (variables["q_ff"].unit, variables["aq_ref"].unit) == ("N*m", "rad/s2")
    t = np.arange(0.0, 0.1, 1e-3)
    columns = {"x_ref": 0.01 + 0 * t, "vx_ref": 0.01 + 0 * t, "ax_ref": 0.5 + 0 * t,
               "jx_ref": 0 * t, "q_ref": 0.2 + 0 * t, "vq_ref": -0.3 + 0 * t,
               "aq_ref": 1.5 + 0 * t, "jq_ref": 0 * t}
    signals = np.array([(ti, *(c[k] for c in columns.values())) for k, ti in enumerate(t)],
                       dtype=[("time", float)] + [(n, float) for n in columns])
    result = fmpy.simulate_fmu(str(fmu), stop_time=0.09, step_size=1e-3, input=signals,
                               output=["x_ff", "q_ff"])
    k = 50
    expected = MASS * [0.5, 1.5] + DAMPING * [0.01, -0.3] + 0.1 * np.sin([0.01, 0.2])
    np.testing.assert_allclose([result["x_ff"][k], result["q_ff"][k]], expected, rtol=1e-9)


def test_a_model_of_other_sizes_is_refused():
    pos, vel, acc = (ca.SX.sym(n, 3) for n in ("pos", "vel", "acc"))
    wrong = ca.Function("wrong", [pos, vel, acc], [pos + vel + acc])
    with pytest.raises(InputError, match="needs positions, velocities, accelerations of its 2"):
        inverse_model_system(stage(), wrong, 1e-3, "wrong")


def test_a_lead_evaluates_the_model_that_far_ahead_on_the_reference(tmp_path):
    """Efforts act half a step after they are commanded (a held effort): with that lead the
    FMU gives the model's effort on the reference's Taylor series that far ahead."""
    lead = 5e-4
    fmu = build_fmu(inverse_model_system(stage(), inverse(), 1e-3, "ahead", lead),
                    tmp_path / "ff.fmu")
    t = np.arange(0.0, 0.1, 1e-3)
    p, v, a, j = 0.01, 0.02, 0.5, 40.0  # constant jerk on x, q at rest
    columns = {"x_ref": p + 0 * t, "vx_ref": v + 0 * t, "ax_ref": a + 0 * t, "jx_ref": j + 0 * t,
               "q_ref": 0 * t, "vq_ref": 0 * t, "aq_ref": 0 * t, "jq_ref": 0 * t}
    signals = np.array([(ti, *(c[k] for c in columns.values())) for k, ti in enumerate(t)],
                       dtype=[("time", float)] + [(n, float) for n in columns])
    result = fmpy.simulate_fmu(str(fmu), stop_time=0.09, step_size=1e-3, input=signals,
                               output=["x_ff"])
    ahead = (p + v * lead + a * lead**2 / 2 + j * lead**3 / 6, v + a * lead + j * lead**2 / 2,
             a + j * lead)
    expected = MASS[0] * ahead[2] + DAMPING[0] * ahead[1] + 0.1 * np.sin(ahead[0])
    assert result["x_ff"][50] == pytest.approx(expected, rel=1e-12)
    assert expected != pytest.approx(MASS[0] * a + DAMPING[0] * v + 0.1 * np.sin(p), rel=1e-3)
