"""The plant FMU against the CasADi model it came from, a tight-tolerance reference and libcosim."""

import fmpy.validation
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error
from scipy.integrate import solve_ivp

from flexff.fmu.fmpy_instance import FmpyInstance
from flexff.fmu.validation import validate_fmu
from flexff.plant.model import PlantModel
from flexff.plant.system import plant_system
from tests.fmu_toys import LoggedSlave, rk4_reference, status_of
from tests.runners import run_fmu, run_fmu_libcosim

STEPS = 1500
H = 1e-3
START = {"x_start": 0.02, "y_start": -0.01}


def driven_currents(steps=STEPS):
    """Piecewise-constant currents that change every 100 ms (so a reference can integrate
    each constant piece exactly), strong enough to cross the whole workspace."""
    t = np.repeat(np.arange(steps // 100 + 1) * 0.1, 100)[:steps]
    return {f"i{k}": 1.5 * np.sin(2 * np.pi * 0.7 * t + 2.1 * k) for k in (1, 2, 3)}


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_fmpy_validation_passes(plant_fmus, variant):
    assert fmpy.validation.validate_fmu(str(plant_fmus[variant])) == []
    assert validate_fmu(plant_fmus[variant]) == []


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
@pytest.mark.parametrize("driven", [False, True], ids=["free", "driven"])
def test_fmu_equals_casadi_rk4(plant_fmus, variant, driven):
    system = plant_system(variant)
    steps = 400
    currents = driven_currents(steps) if driven else {f"i{k}": np.zeros(steps) for k in (1, 2, 3)}
    states = [s.name for s in system.states]
    fmu = run_fmu(plant_fmus[variant], steps, H, inputs=currents, parameters=START, record=states)
    reference = rk4_reference(system, START, np.column_stack(list(currents.values())),
                              [(H, 1)] * steps)
    ours = np.column_stack([fmu[n] for n in states])
    assert np.abs(ours - reference).max() <= 1e-12
    assert np.ptp(ours[:, 0]) > 1e-3  # it really moved


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_fmu_matches_tight_tolerance_scipy_reference(plant_fmus, variant):
    """With sub-steps of 0.1 ms the FMU's RK4 agrees with scipy's DOP853 (rtol 1e-12) to 1e-8."""
    model = PlantModel(variant)
    params = model.parameter_values()
    currents = driven_currents()
    fmu = run_fmu(plant_fmus[variant], STEPS, H, inputs=currents,
                  parameters={**START, "max_substep": 1e-4}, record=["x", "y", "vx", "vy"])
    x = np.array(model.initial_state([START["x_start"], START["y_start"]], params)).ravel()
    reference = [x[:4]]
    for piece in range(STEPS // 100):
        u = [c[piece * 100] for c in currents.values()]

        def rhs(t, s, u=u):
            return np.array(model.forward_dynamics(s, u, params)).ravel()

        solution = solve_ivp(rhs, (0.0, 0.1), x, method="DOP853", rtol=1e-12, atol=1e-14,
                             t_eval=np.linspace(0.0, 0.1, 101)[1:])
        reference += list(solution.y[:4].T)
        x = solution.y[:, -1]
    reference = np.array(reference)
    ours = np.column_stack([fmu[n] for n in ("x", "y", "vx", "vy")])
    assert np.abs(ours[:, :2] - reference[:, :2]).max() < 1e-8  # m
    assert np.abs(ours[:, 2:] - reference[:, 2:]).max() < 1e-8  # m/s
    assert np.ptp(ours[:, 0]) > 0.01


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_libcosim_equals_fmpy(plant_fmus, variant):
    record = ["theta_s1", "theta_s2", "theta_s3", "x", "y", "vx", "vy"]
    parameters = {**START, "seed": 5}
    currents = driven_currents(600)
    ours = run_fmu(plant_fmus[variant], 600, H, currents, parameters, record)
    theirs = run_fmu_libcosim(plant_fmus[variant], 600, H, currents, parameters, record)
    for name in record:
        assert np.abs(theirs[name] - ours[name][1:]).max() <= 1e-12, name


def test_outputs_are_encoders_and_saturated_torques(plant_fmus):
    """Quantization on: whole counts from home; off (the nominal default): the exact angle."""
    currents = {"i1": 14.0, "i2": -3.0, "i3": -20.0}
    counted = run_fmu(plant_fmus["nominal"], 50, H, inputs=currents,
                      parameters={**START, "encoder_quantization": 1.0})
    exact = run_fmu(plant_fmus["nominal"], 50, H, inputs=currents, parameters=START)
    model = PlantModel("nominal")
    p = model.parameter_values()
    start = dict(zip(model.variant.parameters.names(), p))
    resolution = 2 * np.pi / start["encoder_counts"]
    home = np.array(model.coordinates([0.0, 0.0], p)).ravel()[[2, 8, 14]]
    for k in (1, 2, 3):
        counts = (counted[f"theta_s{k}"] - home[k - 1]) / resolution
        assert np.abs(counts - np.round(counts)).max() < 1e-6
        assert np.ptp(counts) > 0.5  # the arm moved by at least one count
        angles = [float(model.coordinates([x, y], p)[[2, 8, 14][k - 1]])
                  for x, y in zip(exact["x"], exact["y"])]
        assert np.abs(exact[f"theta_s{k}"] - angles).max() < 1e-12
        assert np.abs(counted[f"theta_s{k}"] - angles).max() <= resolution / 2 + 1e-12
    limit = start["i_max"]
    for k, i in enumerate(currents.values(), start=1):
        expected = start[f"k_t{k}"] * np.clip(i, -limit, limit)
        assert counted[f"tau{k}"][-1] == pytest.approx(expected, rel=1e-15)


def test_encoder_noise_is_seeded_and_survives_state_round_trip(plant_fmus):
    path = plant_fmus["hardware"]
    with FmpyInstance(path) as s:
        s.initialize({"seed": 3, **START})
        for k in range(100):
            s.fmu.doStep(k * H, H)
        saved = s.fmu.getFMUstate()
        first = []
        for k in range(100, 300):
            s.set({"i1": 1.0})
            s.fmu.doStep(k * H, H)
            first.append(s.get(["theta_s1", "theta_s2", "x"]))
        s.fmu.setFMUstate(saved)
        again = []
        for k in range(100, 300):
            s.set({"i1": 1.0})
            s.fmu.doStep(k * H, H)
            again.append(s.get(["theta_s1", "theta_s2", "x"]))
    assert np.array_equal(np.array(first), np.array(again))


@pytest.mark.parametrize("name", ["m_up2", "k_e1", "encoder_counts"])
def test_bad_physical_parameter_is_rejected_by_name(plant_fmus, name):
    slave = LoggedSlave(str(plant_fmus["nominal"]))
    with pytest.raises(FMICallException):
        slave.initialize(**{name: 0.0})
    assert name in slave.log()
    slave.free()


@pytest.mark.parametrize("variant", ["nominal", "hardware"])
def test_a_start_out_of_reach_is_refused_naming_it(plant_fmus, variant):
    """A start position the arms cannot reach has no encoder angles: initialization is refused,
    naming the output and x_start / y_start (it initialized and read NaN with fmi2OK); a
    reachable start then initializes."""
    slave = LoggedSlave(str(plant_fmus[variant]))
    f = slave.slave
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    slave.set(x_start=0.5, y_start=0.01)
    assert status_of(f.exitInitializationMode) == fmi2Error
    assert "Initial output 'theta_s1' = -nan is not finite" in slave.log()
    assert "for the parameters set (x_start = 0.5, y_start = 0.01)" in slave.log()
    slave.set(**START)  # still in initialization mode
    f.exitInitializationMode()
    assert np.isfinite(slave.get("theta_s1", "theta_s2", "theta_s3")).all()
    slave.free()


def test_the_start_position_is_fixed(plant_fmus):
    """x_start and y_start are initial conditions: fixed parameters, refused after
    initialization (they were declared tunable and ignored)."""
    md = read_model_description(str(plant_fmus["nominal"]))
    variability = {v.name: v.variability for v in md.modelVariables}
    assert variability["x_start"] == variability["y_start"] == "fixed"
    assert variability["k_e1"] == "tunable"
    slave = LoggedSlave(str(plant_fmus["nominal"]))
    slave.initialize(**START)
    assert status_of(lambda: slave.set(x_start=0.0)) == fmi2Error
    assert "parameter 'x_start' is fixed (an initial condition)" in slave.log()
    assert slave.get("x_start") == [START["x_start"]]
    slave.set(k_e1=slave.get("k_e1")[0] * 1.01)  # the physical parameters stay tunable
    slave.free()
