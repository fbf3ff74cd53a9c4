"""ILC that diverges (learning.ilc): a model of the wrong sign (a negative identified mass)
or a plant driven off stops the iteration, keeps its best trial and says so in one line; the
loop's [machine.ilc] settings; identification that warns of an unphysical fit."""

import json
import warnings
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from flexff import cli
from flexff.cosim.config import load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import IlcSettings, parse_machine
from flexff.cosim.master import NonFinite
from flexff.learning import ilc_loops
from flexff.learning.ilc import DIVERGED, RESULT, ilc
from flexff.learning.linear_model import IdentificationWarning, identify_linear

EXAMPLE = Path(__file__).parents[2] / "flexff" / "machines" / "examples" / "drive.toml"


def drive_loop(**ilc_settings):
    loop = load_config(EXAMPLE)
    return replace(loop, stop=2.0, machine=replace(loop.machine,
                                                   ilc=IlcSettings(**ilc_settings)))


def negative_mass(machine, recording):
    """The drive's model with its 2 kg mass of the wrong sign, as a bad identification gives."""
    p, v, a = (ca.SX.sym(n, 1) for n in "pva")
    return ca.Function("negative_mass", [p, v, a], [-2.0 * a + 20.0 * v])


def test_a_model_of_the_wrong_sign_stops_the_iteration_and_keeps_the_best_trial(tmp_path):
    """Measured: e2 4.9e-5 (PID alone), 1.09e-5, 1.12e-5, 1.47e-5, 2.62e-5: stopped at 4."""
    said = []
    state = ilc(drive_loop(), tmp_path, iterations=12, progress=False, say=said.append,
                model=negative_mass)
    stopped = state[DIVERGED]["trial"]
    assert stopped < 12 and len(state["trials"]) == stopped + 1
    e2 = [t["x"]["e2"] for t in state["trials"]]
    assert state["best"] == int(np.argmin(e2)) and e2[-1] > 2 * min(e2)
    assert "e2 on x grew" in state[DIVERGED]["reason"]
    best = np.loadtxt(tmp_path / "tables" / f"trial-{state['best']:03d}.csv", delimiter=",",
                      skiprows=1)
    np.testing.assert_array_equal(np.loadtxt(tmp_path / RESULT, delimiter=",", skiprows=1),
                                  best)
    line = [s for s in said if s.startswith("ILC diverged")]
    assert len(line) == 1 and "\n" not in line[0]
    assert f"trial {stopped}" in line[0] and f"keeping trial {state['best']}" in line[0]
    assert json.loads((tmp_path / "ilc.json").read_text())[DIVERGED] == state[DIVERGED]
    again = ilc(drive_loop(), tmp_path, iterations=12, progress=False, say=said.append,
                model=negative_mass)  # a diverged iteration is not continued
    assert again["trials"] == state["trials"] and said[-1] == line[0]


@pytest.mark.parametrize("how", ["fails", "nan"])
def test_a_run_that_fails_or_goes_non_finite_after_learning_is_a_divergence(tmp_path,
                                                                            monkeypatch, how):
    run = ilc_loops.MachineLoop.trial

    def failing(self, table, trial):
        if trial == 2 and how == "fails":
            raise NonFinite("drive: output 'x' is nan at t = 0.5 s: a non-finite value stops "
                            "the run")
        done = run(self, table, trial)
        if trial == 2:  # a loop that lets non-finite values through (allow_nonfinite)
            done.error[500:] = np.nan
        return done

    monkeypatch.setattr(ilc_loops.MachineLoop, "trial", failing)
    state = ilc(drive_loop(), tmp_path, iterations=4, progress=False, say=lambda _: None,
                floor=False)
    assert state[DIVERGED]["trial"] == 2
    assert ("is nan" if how == "fails" else "not finite") in state[DIVERGED]["reason"]
    assert len(state["trials"]) == 2 and state["best"] in (0, 1)
    assert not (tmp_path / "tables" / "trial-003.csv").exists()


def test_the_loop_s_ilc_settings_are_the_defaults_and_options_override_them(tmp_path):
    state = ilc(drive_loop(iterations=1, cutoff_hz=40.0, gain=0.5), tmp_path / "a",
                progress=False, say=lambda _: None, floor=False)
    assert (len(state["trials"]), state["cutoff_hz"], state["gain"]) == (2, 40.0, 0.5)
    state = ilc(drive_loop(iterations=1, cutoff_hz=40.0), tmp_path / "b", iterations=2,
                cutoff_hz=30.0, gain=0.8, progress=False, say=lambda _: None, floor=False)
    assert (len(state["trials"]), state["cutoff_hz"], state["gain"]) == (3, 30.0, 0.8)


@pytest.mark.parametrize("table, key", [
    ({"iterations": 0}, "machine.ilc.iterations"),
    ({"gain": -1.0}, "machine.ilc.gain"),
    ({"cutoff": 5.0}, "machine.ilc.cutoff"),
])
def test_bad_ilc_settings_are_refused_naming_the_key(table, key):
    description = {"axis": [{"name": "x", "measured": "p.x", "feedforward": "c.x_ff",
                             "effort": "c.u", "range": [-1, 1], "velocity": 1,
                             "acceleration": 1}], "ilc": table}
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        parse_machine(description, "m.toml")


def test_the_cli_sets_ilc_s_gain_and_refuses_a_bad_one(tmp_path, capsys):
    assert cli.main(["ilc", str(EXAMPLE), "-o", str(tmp_path), "--gain", "0"]) == 2
    assert "learning gain 0" in capsys.readouterr().err
    options = cli.build_parser().parse_args(["evaluate", "--config", "x.toml", "-o", "o",
                                             "--ilc-iterations", "3", "--ilc-cutoff", "50",
                                             "--ilc-gain", "0.5"])
    assert (options.ilc_iterations, options.ilc_cutoff, options.ilc_gain) == (3, 50.0, 0.5)


def one_axis():
    return parse_machine({"axis": [{"name": "z", "measured": "p.z", "feedforward": "c.z_ff",
                                    "effort": "c.u", "range": [-0.05, 0.05], "velocity": 0.5,
                                    "acceleration": 5.0}],
                          "prior": {"terms": ["inertia", "viscous", "coulomb"],
                                    "coulomb_width": 2e-3}}, "m")


def motion(seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 10.0, 1e-3)
    f, phase = rng.uniform(0.2, 2.0, 4), rng.uniform(0, 2 * np.pi, 4)
    w = 2 * np.pi * f[:, None]
    amplitude = 0.01 * f.min() / f[:, None]
    return {"z": (amplitude * np.sin(w * t + phase[:, None])).sum(0),
            "vz": (amplitude * w * np.cos(w * t + phase[:, None])).sum(0),
            "az": -(amplitude * w**2 * np.sin(w * t + phase[:, None])).sum(0)}


def test_a_negative_mass_is_warned_of_naming_the_term():
    m = motion()
    effort = -3.0 * m["az"] + 10.0 * m["vz"] + 1.0 * np.tanh(m["vz"] / 2e-3)
    with pytest.warns(IdentificationWarning) as caught:
        fit = identify_linear(one_axis(), m, {"z": effort}).axes["z"]
    assert fit.parameters[0] == pytest.approx(-3.0)
    assert len(caught) == 1
    assert str(caught[0].message).startswith("axis z: the identified inertia is -3 ")


def test_clearly_negative_friction_and_a_huge_condition_number_are_warned_of():
    m = motion(1)
    effort = 2.0 * m["az"] - 10.0 * m["vz"] + np.random.default_rng(0).normal(0, 1e-3, m["z"].size)
    with pytest.warns(IdentificationWarning, match="axis z: the identified viscous is -10"):
        identify_linear(one_axis(), m, {"z": effort})
    near = parse_machine({"axis": [{"name": "z", "measured": "p.z", "feedforward": "c.z_ff",
                                    "effort": "c.u", "range": [-0.05, 0.05], "velocity": 0.5,
                                    "acceleration": 5.0}],
                          "prior": {"terms": ["inertia", "viscous"],
                                    "extra": {"z": {"near": "vz + 1e-3 * z"}}}}, "m")
    with pytest.warns(IdentificationWarning, match=r"axis z: the regressor's condition number "
                                                   r"is [0-9.e+]+ \(above 10000\)"):
        identify_linear(near, m, {"z": 2.0 * m["az"] + 20.0 * m["vz"] + m["z"]})


def test_a_physical_fit_warns_of_nothing():
    m = motion(2)
    effort = 2.0 * m["az"] + 10.0 * m["vz"] + 1.0 * np.tanh(m["vz"] / 2e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", IdentificationWarning)
        identify_linear(one_axis(), m, {"z": effort})


def test_evaluate_keeps_a_diverged_ilc_s_best_trial_and_marks_its_column(tmp_path):
    from flexff.learning.machine_evaluate import _limit, summary_table

    loop = drive_loop()
    m = {f"{d}x": values for d, values in zip(("", "v", "a"), motion(3).values())}
    with pytest.warns(IdentificationWarning, match="axis x: the identified inertia is -2"):
        identified = identify_linear(loop.machine, m, {"x": -2.0 * m["ax"] + 20.0 * m["vx"]})
    with pytest.warns(UserWarning, match=r"^ILC diverged at trial \d+ \(e2 on x grew"):
        limit, record, line = _limit(loop, tmp_path, identified, 12, None, None, False)
    assert record[DIVERGED] == limit[DIVERGED] and record["best"] == limit["best"]
    best = next(t for t in limit["trials"] if t["trial"] == limit["best"])
    summary = {"axes": ["x"], "ilc": record, "scenarios": {
        "pid": {"x": {"e2": 1.0, "e2_ratio": 1.0}},
        "ilc": {"x": {"e2": best["x"]["e2"], "e2_ratio": best["x"]["e2_ratio"]}}}}
    table = summary_table(summary, line)
    assert table.startswith("| axis | pid | ilc (diverged: best so far) |")
    assert table.rstrip().endswith(line.rstrip()) and "ILC diverged at trial" in table
