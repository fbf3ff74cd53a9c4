"""The PID block in its parallel form (built-in "pid-gains": blocks.pid), sum and
gain (blocks.sum_gain) as FMUs: validated, run by FMPy, their discrete responses checked against
hand computations."""

import math

import numpy as np
import pytest

from flexff import api
from flexff.blocks.options import OptionError
from flexff.blocks.pid import pid_system
from flexff.blocks.pid_design import AxisPid, Gains, LoopShape
from flexff.blocks.pid_options import pid_gains_from_options as pid_from_options
from flexff.blocks.sum_gain import gain_from_options, sum_from_options
from flexff.fmu.build import build_fmu
from flexff.fmu.validation import validate_fmu
from tests.runners import run_fmu, simulate_with_fmpy

STEP = 1e-3
KP, KI, KD, FILTER_HZ = 2.0, 3.0, 0.01, 50.0
LIMIT = 2.0
NOTCH_HZ, NOTCH_ZETA, LOWPASS_HZ = 100.0, (0.02, 0.5), 50.0


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blocks")
    limited = {"axes": ["x"], "kp": 1.0, "ki": 100.0, "effort_limit": LIMIT}
    systems = {
        "pid": pid_from_options({"axes": ["x", "y"], "kp": {"x": KP, "y": 1.0}, "ki": KI,
                                 "kd": {"x": KD}, "derivative_filter_hz": FILTER_HZ}, STEP),
        "back_calculation": pid_from_options(limited, STEP),
        "clamp": pid_from_options({**limited, "anti_windup": "clamp"}, STEP),
        "unlimited": pid_from_options({"axes": ["x"], "kp": 1.0, "ki": 100.0}, STEP),
        "filtered": pid_system({"x": AxisPid(Gains(1.0), notch_hz=NOTCH_HZ,
                                             notch_zeta=NOTCH_ZETA),
                                "y": AxisPid(Gains(1.0), lowpass_hz=LOWPASS_HZ)}, STEP),
        "sum": sum_from_options({"inputs": ["a", "b"], "output": "c", "signs": [1, -2]}, STEP),
        "gain": gain_from_options({"input": "a", "output": "b", "gain": 3.0}, STEP),
    }
    return {name: build_fmu(s, folder / f"{name}.fmu") for name, s in systems.items()}


def test_blocks_validate(fmus):
    for name in ("pid", "back_calculation", "filtered", "sum", "gain"):
        assert validate_fmu(fmus[name]) == [], name


def test_pid_step_in_error_matches_the_hand_computation(fmus):
    """e = 1 from t = 0, feedforward 0.5: effort_k = kp + ki t_k + kd (1 - a) a^k / step + 0.5,
    a = tau / (tau + step), tau = 1 / (2 pi derivative_filter_hz); the y axis runs on its own."""
    inputs = {"x_ref": lambda t: 1.0, "x_ff": lambda t: 0.5, "y_ref": lambda t: 0.0,
              "y": lambda t: -2.0}
    r = simulate_with_fmpy(fmus["pid"], inputs, 0.05, ["x_effort", "x_fb", "y_effort"])
    t, k = r["time"], np.arange(len(r))
    tau = 1 / (2 * math.pi * FILTER_HZ)
    a = tau / (tau + STEP)
    fb = KP + KI * t + KD * (1 - a) * a**k / STEP
    np.testing.assert_allclose(r["x_fb"], fb, rtol=1e-12)
    np.testing.assert_allclose(r["x_effort"], fb + 0.5, rtol=1e-12)
    np.testing.assert_allclose(r["y_effort"], 2.0 + 2.0 * KI * t, rtol=1e-12)


def test_anti_windup_bounds_the_integrator_and_releases_at_once(fmus):
    """e = +1 for 1 s (effort saturated at 2), then e = -1. Back-calculation with the default
    tracking gain ki / kp settles at I = limit - kp e + ki e / gain = 2; the clamp holds I at 2;
    without a limit I reaches ki t = 100 and the effort stays positive long after the reversal."""
    error = {"x_ref": lambda t: 1.0 if t < 1.0 else -1.0}
    ends = {}
    for name in ("back_calculation", "clamp", "unlimited"):
        r = simulate_with_fmpy(fmus[name], error, 1.2, ["x_integral", "x_effort"])
        before, after = r["time"] < 1.0, r["time"] > 1.0
        ends[name] = r["x_integral"][before][-1]
        if name != "unlimited":
            assert np.max(np.abs(r["x_effort"])) <= LIMIT
            assert np.max(r["x_integral"]) <= LIMIT + 1e-9
            released = r["time"][after & (r["x_effort"] < 0)][0]
            assert released < 1.03, name  # the effort turns within 30 ms of the reversal
        else:
            assert np.all(r["x_effort"][after] > 0)
    assert ends["back_calculation"] == pytest.approx(2.0, rel=1e-6)
    assert ends["clamp"] == pytest.approx(LIMIT)
    assert ends["unlimited"] == pytest.approx(100.0 * 0.999, rel=1e-6)


def _amplitude(r, name, hz):
    """Amplitude of the `hz` sine in the second half of signal `name` (least squares)."""
    keep = r["time"] > r["time"][-1] / 2
    t = r["time"][keep]
    basis = np.column_stack([np.sin(2 * math.pi * hz * t), np.cos(2 * math.pi * hz * t)])
    coefficients = np.linalg.lstsq(basis, r[name][keep], rcond=None)[0]
    return float(np.hypot(*coefficients))


@pytest.mark.parametrize(("hz", "notch_gain", "lowpass_gain"),
                         [(NOTCH_HZ, NOTCH_ZETA[0] / NOTCH_ZETA[1], None),
                          (LOWPASS_HZ, None, 1 / math.sqrt(2)), (5.0, 1.0, 1.0)])
def test_notch_and_lowpass_attenuate_at_their_frequencies(fmus, hz, notch_gain, lowpass_gain):
    """A sine error through kp = 1: depth z1 / z2 at the notch's centre, 1 / (2 zeta) at the
    low-pass corner (prewarped Tustin: exact there), unity far below; the simulated amplitude
    matches the block's own frequency response at every frequency. Run through FMPy's low-level
    API with each output read after its step's inputs are set (tests.runners), as a master
    does: fmpy.simulate_fmu reads a direct feedthrough one input late."""
    steps = 600
    sine = np.sin(2 * math.pi * hz * STEP * np.arange(steps))
    r = run_fmu(fmus["filtered"], steps, STEP, {"x_ref": sine, "y_ref": sine},
                record=["x_fb", "y_fb"])
    r = {name: values[:steps] for name, values in r.items()}
    w = 2 * math.pi * hz
    for axis, expected, pid in (("x", notch_gain, AxisPid(Gains(1.0), notch_hz=NOTCH_HZ,
                                                          notch_zeta=NOTCH_ZETA)),
                                ("y", lowpass_gain, AxisPid(Gains(1.0), lowpass_hz=LOWPASS_HZ))):
        measured = _amplitude(r, f"{axis}_fb", hz)
        response = abs(pid.state_space(STEP).response(w)[0])
        assert measured == pytest.approx(response, rel=1e-3)
        if expected is not None:
            assert measured == pytest.approx(expected, rel=0.05 if hz == 5.0 else 1e-3)


def test_loop_shaped_design_crosses_over_where_asked():
    pid = AxisPid(LoopShape(30.0, 2.0), notch_hz=200.0)
    margins = pid.margins(STEP)
    assert margins.crossover_hz == pytest.approx(30.0, rel=1e-6)
    assert margins.phase_margin_deg > 30
    assert margins.gain_margin_db > 6
    from_options = pid_from_options({"axes": ["x"], "crossover_hz": 30.0, "mass": 2.0,
                                     "notch_hz": 200.0}, STEP)
    kp = next(p for p in from_options.parameters if p.name == "kp_x")
    assert kp.start == pytest.approx(pid.parallel_gains(STEP).kp)


def test_sum_and_gain(fmus):
    ramp = 1.0 + STEP * np.arange(10)
    r = run_fmu(fmus["sum"], 10, STEP, {"a": ramp, "b": 3.0}, record=["c"])
    np.testing.assert_allclose(r["c"][:10], ramp - 6.0, atol=1e-12)
    r = simulate_with_fmpy(fmus["gain"], {"a": lambda t: 2.0}, 0.01, ["b"], gain=-1.5)
    np.testing.assert_allclose(r["b"], -3.0)


@pytest.mark.parametrize(("options", "key"), [
    ({"axes": ["x"], "kp": 1.0, "speed": 2}, "'speed'"),
    ({"axes": ["x"], "crossover_hz": 10.0}, "'x'"),
    ({"axes": ["x"], "crossover_hz": 10.0, "mass": 1.0, "kp": 3.0}, "drop kp"),
    ({"axes": ["x"], "kp": {"z": 1.0}}, "'kp'"),
    ({"axes": ["x"], "kp": -1.0, "effort_limit": -2.0}, "'effort_limit'"),
    ({"axes": "x", "kp": 1.0}, "'axes'"),
    ({"axes": ["x"], "kp": 1.0, "notch_hz": 600.0}, "notch"),
    ({"axes": ["x"], "kp": 1.0, "effort_limit": 1.0, "anti_windup": "none"}, "'anti_windup'"),
    ({"axes": ["x"], "kp": 1.0, "anti_windup": "clamp"}, "effort_limit"),
])
def test_pid_options_name_the_key_at_fault(options, key):
    with pytest.raises(OptionError, match=key):
        pid_from_options(options, STEP)


def test_sum_and_gain_run_as_builtins(tmp_path):
    """The registry path: built-in sum and gain named in a configuration, chained by name."""
    config = tmp_path / "chain.toml"
    config.write_text("""
[run]
step = 0.001
stop = 0.01

[[source]]
kind = "constant"
values = { a = 1.5, b = 0.25 }

[fmu.total]
builtin = "sum"
inputs = ["a", "b"]
output = "c"
signs = [1, -1]

[fmu.scaled]
builtin = "gain"
input = "c"
output = "d"
gain = 4.0
""")
    recording = api.simulate(api.load(config))
    np.testing.assert_allclose(recording["scaled.d"], 4.0 * (1.5 - 0.25))
