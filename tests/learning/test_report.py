"""The evaluation report: norms and ratios against closed forms, its files, its checks.

The synthetic runs last T = 2 s at 1 ms (N = 2000 steps, 2001 points). A scenario's error is
a * sin(2 pi f t) with f = 1 Hz on x and 2 Hz on y: whole periods, so over k = 0 .. N
sum e_k^2 = a^2 N / 2 (the k = N point adds sin^2 = 0), and the peak a is sampled (at 0.25 s
and 0.125 s). Hence e2 = sqrt(a^2 N/2 dt) / T = a / sqrt(2 T) = a / 2, einf = a and
rms = a sqrt(N / (2 (N + 1))). The rigid-body run has a constant error c instead:
e2 = c sqrt((N + 1) dt) / T, einf = rms = c.
"""

import json
import math

import numpy as np
import pytest

from flexff.cosim.metrics import named_axes, tracking_metrics
from flexff.cosim.recording import Recording
from flexff.learning.report import (
    NO_FLOOR,
    SCENARIO_LABELS,
    THESIS_TABLES,
    floor_note,
    force_gap_table,
    held_out_table,
    markdown_table,
    own_share_table,
    summarize,
    write_report,
)
from flexff.plant.signals import AXES

STEP, N = 1e-3, 2000
T = N * STEP
PID_X, PID_Y = 2e-3, 1e-3          # amplitudes of PID alone's errors [m]
RIGID_C = 1e-4                     # the rigid-body run's constant error [m], both axes
FIVE = ["summary.json", "table.md", "paths.png", "errors.png", "forces.png"]
XY = named_axes(AXES)  # the manipulator's tracked axes


def run(error_x, error_y, ff_gain: float = 1.0, step: float = STEP, n: int = N) -> Recording:
    """A circle reference followed with the given errors (callables of time)."""
    t = np.arange(n + 1) * step
    x_ref, y_ref = 0.014 * np.cos(2 * np.pi * t), 0.014 * np.sin(2 * np.pi * t)
    force = np.sin(4 * np.pi * t)
    return Recording(t, {"x_ref": x_ref, "y_ref": y_ref,
                         "x": x_ref - error_x(t), "y": y_ref - error_y(t),
                         "Fx_fb": (1 - ff_gain) * force, "Fy_fb": 0.5 * (1 - ff_gain) * force,
                         "Fx_ff": ff_gain * force, "Fy_ff": 0.5 * ff_gain * force})


def sines(scale: float, ff_gain: float = 1.0, **kwargs) -> Recording:
    return run(lambda t: scale * PID_X * np.sin(2 * np.pi * t),
               lambda t: scale * PID_Y * np.sin(4 * np.pi * t), ff_gain, **kwargs)


def scenarios() -> dict[str, Recording]:
    """PID alone, an LSTM with 1/50 of its error, TCN with 1/8, rigid body with a constant."""
    return {"pid": sines(1.0, ff_gain=0.0), "lstm": sines(1 / 50), "tcn": sines(1 / 8),
            "rigid-body": run(lambda t: np.full_like(t, RIGID_C),
                              lambda t: np.full_like(t, RIGID_C), 0.9)}


def sine_norms(a: float) -> dict[str, float]:
    return {"e2": a / 2, "einf": a, "rms": a * math.sqrt(N / (2 * (N + 1)))}


def test_summarize_against_closed_forms():
    recs = scenarios()
    summary = summarize({name: tracking_metrics(rec, XY) for name, rec in recs.items()})
    assert list(summary) == ["pid", "lstm", "tcn", "rigid-body"]
    for name, scale in (("pid", 1.0), ("lstm", 1 / 50), ("tcn", 1 / 8)):
        for axis, a in (("x", PID_X), ("y", PID_Y)):
            got = summary[name][axis]
            assert set(got) == {"rms", "e2", "einf", "rms_ratio", "e2_ratio", "einf_ratio"}
            for key, value in sine_norms(scale * a).items():
                assert got[key] == pytest.approx(value, rel=1e-9), (name, axis, key)
            for key in ("rms_ratio", "e2_ratio", "einf_ratio"):
                assert got[key] == pytest.approx(1 / scale, rel=1e-9), (name, axis, key)
    assert summary["pid"]["x"]["e2_ratio"] == summary["pid"]["y"]["einf_ratio"] == 1.0
    rigid_e2 = RIGID_C * math.sqrt((N + 1) * STEP) / T
    for axis, a in (("x", PID_X), ("y", PID_Y)):
        got = summary["rigid-body"][axis]
        assert got["e2"] == pytest.approx(rigid_e2, rel=1e-9)
        assert got["einf"] == pytest.approx(RIGID_C, rel=1e-9)
        assert got["rms"] == pytest.approx(RIGID_C, rel=1e-9)
        assert got["e2_ratio"] == pytest.approx((a / 2) / rigid_e2, rel=1e-9)
        assert got["einf_ratio"] == pytest.approx(a / RIGID_C, rel=1e-9)


def test_summarize_puts_pid_first_and_has_no_ratio_for_a_perfect_run():
    norms = {"x": {"e2": 1e-3, "einf": 2e-3, "rms": 1e-3}, "y": {"e2": 0.0, "einf": 0.0,
                                                               "rms": 0.0}}
    pid = {"x": {"e2": 4e-3, "einf": 4e-3, "rms": 4e-3}, "y": {"e2": 1e-3, "einf": 1e-3,
                                                              "rms": 1e-3}}
    summary = summarize({"tcn": norms, "pid": pid})
    assert list(summary) == ["pid", "tcn"]
    assert summary["tcn"]["x"]["e2_ratio"] == 4.0 and summary["tcn"]["x"]["einf_ratio"] == 2.0
    assert summary["tcn"]["y"]["e2_ratio"] is None and summary["tcn"]["y"]["einf_ratio"] is None


def test_thesis_tables_in_si_units():
    sim, hardware = THESIS_TABLES["sim"], THESIS_TABLES["hardware"]
    assert list(sim) == ["pid", "lstm", "cnn-lstm", "tcn"] and list(hardware) == ["pid", "lstm",
                                                                                  "tcn"]
    # the thesis's ‖E‖₂ is an rms: as e2 = rms / sqrt(15 s) its PID alone would have an rms
    # above its own largest error
    assert sim["pid"]["x"]["rms"] * math.sqrt(15.0) > sim["pid"]["x"]["einf"]
    assert sim["pid"]["x"] == {"rms": 0.004293, "einf": 0.014223}
    assert sim["cnn-lstm"]["y"] == {"rms": 0.0016648, "einf": 0.007234}
    assert hardware["tcn"]["y"] == {"rms": 0.003446, "einf": 0.009361}
    assert hardware["pid"]["x"] == {"rms": 0.003585, "einf": 0.00782}
    assert set(SCENARIO_LABELS) >= set(sim) | {"rigid-body", "pgnn"}


def test_markdown_table_sim_and_hardware():
    summary = summarize({name: tracking_metrics(rec, XY) for name, rec in scenarios().items()})
    sim = markdown_table(summary, "sim")
    lines = sim.splitlines()
    assert "x 1e-4" in lines[0] and "e2 in m/√s" in lines[0]
    header = [cell.strip() for cell in lines[2].strip("|").split("|")]
    assert header == ["error (x 1e-4)", "PID alone", "LSTM FF", "TCN FF", "rigid-body FF",
                      "thesis: PID alone", "thesis: LSTM FF", "thesis: CNN-LSTM FF",
                      "thesis: TCN FF"]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]]
            for line in lines[4:10]}
    rms_x, rms_y = "‖E_x‖₂ (rms, as the thesis)", "‖E_y‖₂ (rms, as the thesis)"
    assert list(rows) == [rms_x, rms_y, "e2 x (rms/√T)", "e2 y (rms/√T)", "‖E_x‖∞", "‖E_y‖∞"]
    # PID alone: rms x = 2 mm sqrt(N / (2 (N + 1))) = 14.139e-4, e2 x = 2 mm / 2 = 10e-4,
    # einf x = 20e-4; LSTM 1/50 of it
    assert rows[rms_x][:2] == ["14.139", "0.283 (50x)"]
    assert rows["e2 x (rms/√T)"][:2] == ["10.000", "0.200 (50x)"]
    assert rows["‖E_x‖∞"][:3] == ["20.000", "0.400 (50x)", "2.500 (8x)"]
    assert rows["e2 y (rms/√T)"][:2] == ["5.000", "0.100 (50x)"]
    assert rows[rms_x][4:] == ["42.930", "0.457 (94x)", "10.550 (4.1x)", "1.257 (34x)"]
    assert rows["e2 x (rms/√T)"][4:] == ["–"] * 4  # the thesis gives no e2
    assert rows["‖E_y‖∞"][4:] == ["140.000", "4.032 (35x)", "72.340 (1.9x)", "6.372 (22x)"]
    assert "PID alone / scenario" in lines[-1]

    hardware = markdown_table(summary, "hardware")
    assert "x 1e-3" in hardware.splitlines()[0] and "CNN-LSTM" not in hardware
    for number in ("3.585", "1.985", "1.742", "3.517", "2.624", "3.446", "7.820", "5.150",
                   "4.736", "8.240", "6.952", "9.361"):
        assert number in hardware
    # PID alone's e2 x on the 1e-3 scale; three significant digits below 0.1
    assert "| e2 x (rms/√T) | 1.000 | 0.0200 (50x) |" in hardware


def test_write_report_files(tmp_path):
    out = tmp_path / "report"
    recs = scenarios()
    content = write_report({"lstm": recs["lstm"], "pid": recs["pid"], "tcn": recs["tcn"]},
                           "sim", out)
    assert sorted(p.name for p in out.iterdir()) == sorted(FIVE)  # no temporary file left
    for name in ("paths.png", "errors.png", "forces.png"):
        data = (out / name).read_bytes()
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 10_000, name
    written = json.loads((out / "summary.json").read_text())
    assert written == content
    assert list(written) == ["env", "scenarios", "thesis", "units"]
    assert written["env"] == "sim" and written["thesis"] == THESIS_TABLES["sim"]
    assert list(written["scenarios"]) == ["pid", "lstm", "tcn"]
    assert written["scenarios"]["lstm"]["x"]["e2"] == pytest.approx(PID_X / 100, rel=1e-9)
    assert written["scenarios"]["tcn"]["y"]["einf_ratio"] == pytest.approx(8.0, rel=1e-9)
    assert written["units"]["e2"] == "m/sqrt(s)" and written["units"]["einf"] == "m"
    table = (out / "table.md").read_text(encoding="utf-8")
    assert table == markdown_table(content["scenarios"], "sim") + "\n" + NO_FLOOR
    assert "own_e2" not in written["scenarios"]["lstm"]["x"]  # no floor, no own share
    assert "42.930" in table and "thesis: CNN-LSTM FF" in table


def test_pid_alone_needs_no_forces_and_writes_no_force_plot(tmp_path):
    pid = scenarios()["pid"]
    tracking = {name: pid[name] for name in ("x_ref", "y_ref", "x", "y")}
    content = write_report({"pid": Recording(pid.time, tracking)}, "hardware", tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(set(FIVE) - {"forces.png"})
    assert content["thesis"] == THESIS_TABLES["hardware"]


@pytest.mark.parametrize("case, match", [
    ("env", "unknown environment 'real'"),
    ("no pid", "no 'pid' scenario"),
    ("signal", "recording 'tcn' lacks \\['Fy_ff'\\]"),
    ("tracking", "recording 'pid' lacks \\['y'\\]"),
    ("length", "recording 'tcn' has 1001 points, 'pid' has 2001"),
    ("step", "recording 'tcn' steps 0.002 s, 'pid' 0.001 s"),
])
def test_write_report_refuses_bad_input_before_writing(tmp_path, case, match):
    recs = scenarios()
    env = "real" if case == "env" else "sim"
    if case == "no pid":
        del recs["pid"]
    if case == "signal":
        recs["tcn"] = Recording(recs["tcn"].time, {k: v for k, v in recs["tcn"].signals.items()
                                                  if k != "Fy_ff"})
    if case == "tracking":
        recs["pid"] = Recording(recs["pid"].time, {k: v for k, v in recs["pid"].signals.items()
                                                  if k != "y"})
    if case == "length":
        recs["tcn"] = sines(1 / 8, n=N // 2)
    if case == "step":
        recs["tcn"] = sines(1 / 8, step=2 * STEP)
    with pytest.raises(ValueError, match=match):
        write_report(recs, env, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_summarize_and_table_checks():
    norms = {"x": {"e2": 1.0, "einf": 1.0, "rms": 1.0}, "y": {"e2": 1.0, "einf": 1.0, "rms": 1.0}}
    with pytest.raises(ValueError, match=r"no 'pid' scenario .*include the PID-alone run"):
        summarize({"lstm": norms})
    with pytest.raises(ValueError, match="unknown environment 'nominal': use 'sim'"):
        markdown_table(summarize({"pid": norms}), "nominal")


def test_every_scenario_as_a_multiple_of_the_ilc_limit():
    """With a "limit" scenario (1/200 of PID alone's error), each scenario's e2 is also given
    as a multiple of the limit's: 200x for PID alone, 4x for the LSTM (1/50), 1x for itself."""
    recordings = {**scenarios(), "limit": sines(1 / 200)}
    summary = summarize({name: tracking_metrics(rec, XY) for name, rec in recordings.items()})
    for axis in ("x", "y"):
        assert summary["pid"][axis]["e2_per_limit"] == pytest.approx(200, rel=1e-9)
        assert summary["lstm"][axis]["e2_per_limit"] == pytest.approx(4, rel=1e-9)
        assert summary["limit"][axis]["e2_per_limit"] == 1.0
    table = markdown_table(summary, "sim")
    assert "| e2 x / ILC limit | 200x | 4x | 25x | " in table
    assert "| e2 y / ILC limit | 200x | 4x | 25x | " in table
    assert "ILC limit" in table.splitlines()[2] and "1x | – | – | – | – |" in table
    without = summarize({name: tracking_metrics(rec, XY) for name, rec in scenarios().items()})
    assert "e2_per_limit" not in without["lstm"]["x"]
    assert "ILC limit" not in markdown_table(without, "sim")


def test_the_noise_floor_goes_into_the_summary_and_under_the_table(tmp_path):
    """Given the floor (half the limit's e2 on each axis), summary.json keeps it and table.md
    says it with the limit as a multiple of it; without a limit the multiple is left out."""
    recordings = {**scenarios(), "limit": sines(1 / 200)}
    limit = tracking_metrics(recordings["limit"], XY)
    floor = {axis: limit[axis]["e2"] / 2 for axis in ("x", "y")}
    content = write_report(recordings, "hardware", tmp_path, noise_floor=floor)
    assert json.loads((tmp_path / "summary.json").read_text())["noise_floor"] == floor
    table = (tmp_path / "table.md").read_text(encoding="utf-8")
    assert table == markdown_table(content["scenarios"], "hardware") + "\n" + floor_note(
        content["scenarios"], floor) + "\n" + own_share_table(content["scenarios"], floor) + \
        "\n" + force_gap_table(content["force_gap"])
    assert set(content["force_gap"]) == set(recordings) - {"pid", "limit"}
    assert f"e2 x, y = {floor['x']:.3g}, {floor['y']:.3g} m/√s" in table
    assert "the ILC limit's is 2x / 2x of it." in table
    assert "ILC limit" not in floor_note(summarize({"pid": limit}), floor)


def test_the_held_out_references_table_gives_each_scenarios_mean_and_worst(tmp_path):
    held = {"references": ["a", "b"],
            "e2_ratio": {"tcn": {"x": [100.0, 400.0], "y": [10.0, 1000.0]}},
            "geometric_mean": {"tcn": {"x": 200.0, "y": 100.0}},
            "worst": {"tcn": {"x": 100.0, "y": 10.0}}}
    content = write_report(scenarios(), "sim", tmp_path, held_out=held)
    assert json.loads((tmp_path / "summary.json").read_text())["held_out"] == held
    table = (tmp_path / "table.md").read_text(encoding="utf-8")
    assert table.endswith(held_out_table(held)) and content["held_out"] == held
    assert "On the 2 references of the test split" in table
    assert "| TCN FF | 200 / 100 | 100 / 10 |" in table


def test_each_scenarios_own_share_of_e2_over_the_floor(tmp_path):
    """With the floor at half the limit's e2 (1/400 of PID alone's), each axis's own share is
    sqrt(e2^2 - floor^2): the limit's sqrt(3)/2 of its e2; summary.json and table.md give it
    beside e2 and its ratio, each own-share column headed with its floor."""
    recordings = {**scenarios(), "limit": sines(1 / 200)}
    limit = tracking_metrics(recordings["limit"], XY)
    floor = {axis: limit[axis]["e2"] / 2 for axis in ("x", "y")}
    write_report(recordings, "hardware", tmp_path, noise_floor=floor)
    written = json.loads((tmp_path / "summary.json").read_text())
    for axis, a in (("x", PID_X), ("y", PID_Y)):
        for name, scale in (("pid", 1.0), ("lstm", 1 / 50), ("limit", 1 / 200)):
            got = written["scenarios"][name][axis]
            e2 = scale * a / 2
            assert got["e2"] == pytest.approx(e2, rel=1e-9)
            assert got["own_e2"] == pytest.approx(math.sqrt(e2**2 - floor[axis]**2), rel=1e-9)
            assert got["at_floor"] is False and "e2_ratio" in got
        assert written["scenarios"]["limit"][axis]["own_e2"] == pytest.approx(
            math.sqrt(3) / 2 * limit[axis]["e2"], rel=1e-9)
    assert written["units"]["own_e2"].startswith("m/sqrt(s)")
    table = (tmp_path / "table.md").read_text(encoding="utf-8")
    assert (f"| scenario | e2 x [m/√s] | ratio x | own share x (floor {floor['x']:.3g}) | "
            f"e2 y [m/√s] | ratio y | own share y (floor {floor['y']:.3g}) |") in table
    own = written["scenarios"]["lstm"]
    assert (f"| LSTM FF | {own['x']['e2']:.3g} | 50x | {own['x']['own_e2']:.3g} | "
            f"{own['y']['e2']:.3g} | 50x | {own['y']['own_e2']:.3g} |") in table


def test_at_or_below_the_floor_the_own_share_is_zero_and_said_so():
    """A scenario whose e2 is at or under the floor (noise alone) has own share 0.0, never
    NaN, and the table says "at the floor"; the axis above it keeps its own share."""
    pid = {"x": {"e2": 1e-3, "einf": 1e-3, "rms": 1e-3}, "y": {"e2": 1e-3, "einf": 1e-3,
                                                              "rms": 1e-3}}
    near = {"x": {"e2": 2e-6, "einf": 1e-5, "rms": 1e-5}, "y": {"e2": 5e-6, "einf": 1e-5,
                                                               "rms": 1e-5}}
    floor = {"x": 3e-6, "y": 3e-6}
    summary = summarize({"pid": pid, "limit": near}, floor)
    assert summary["limit"]["x"]["own_e2"] == 0.0 and summary["limit"]["x"]["at_floor"]
    assert summary["limit"]["y"]["own_e2"] == pytest.approx(4e-6, rel=1e-9)
    assert summary["limit"]["y"]["at_floor"] is False
    assert "| ILC limit | 2e-06 | 500x | at the floor | 5e-06 | 200x | 4e-06 |" in \
        own_share_table(summary, floor)
    assert summarize({"pid": pid, "limit": near}, {"x": 2e-6, "y": 0.0})["limit"]["x"][
        "own_e2"] == 0.0  # e2 exactly on the floor


def test_the_limit_fed_by_its_force_table_is_compared_as_the_controller_received_it(tmp_path):
    """The LIMIT scenario's force comes from ILC's table (x_ff, y_ff feed the controller, no
    Fx_ff is recorded): the force gap and the force plot read it there. A scenario whose
    feedforward is the limit's own force has no gap."""
    limit = sines(1 / 200)
    signals = dict(limit.signals)
    signals["x_ff"], signals["y_ff"] = signals.pop("Fx_ff"), signals.pop("Fy_ff")
    recordings = {**scenarios(), "limit": Recording(limit.time, signals)}
    summary = write_report(recordings, "sim", tmp_path)
    assert summary["force_gap"]["lstm"]["x"]["rms_n"] == 0.0
    assert summary["force_gap"]["rigid-body"]["y"]["rms_n"] > 0.0
    assert (tmp_path / "forces.png").stat().st_size > 0
