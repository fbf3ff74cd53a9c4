"""`flexff tune LOOP`: each axis's plant measured in the loop, the PID block's mass found
within 10 % of the plant's true one, and a crossover proposed whose loop keeps the phase
margin asked for around the identified model and runs stably on the plant itself."""

import tomllib
from dataclasses import replace

import pytest

from flexff.cosim.metrics import machine_axes, tracking_metrics
from flexff.cosim.run import load_run_config, simulate_config
from flexff.fmu.errors import InputError
from flexff.learning.pid_tune import (
    GAIN_MARGIN_DB,
    margins_of,
    tune_loop,
    tuned_loop,
    tuning_toml,
)
from flexff.machines.drive import DRIVE
from tests.helpers import REPOSITORY

EXAMPLES = REPOSITORY / "flexff" / "machines" / "examples"


def test_the_drive_is_measured_and_its_tuned_loop_keeps_the_margin():
    loop = load_run_config(EXAMPLES / "drive.toml")
    tuning = tune_loop(loop, 45.0, seconds=3.0)
    (axis,) = tuning.axes
    assert axis.mass == pytest.approx(DRIVE.mass, rel=0.1)  # 2 kg, carriage and its load
    assert axis.damping == pytest.approx(DRIVE.viscous, rel=0.1)
    assert axis.crossover_hz is not None and axis.margins is not None
    # the margin asked for, around the identified model, with the block's own design
    design = tuning.block
    assert design is not None and design.name == "pid"
    from flexff.blocks.pid_options import axes_from_options

    pid = axes_from_options(design.options, loop.step, "series", "pid")["x"]
    margins = margins_of(pid, axis.mass, axis.damping, axis.crossover_hz, axis.delay_s,
                         loop.step)
    assert margins.phase_margin_deg >= 45.0 and margins.gain_margin_db >= GAIN_MARGIN_DB
    # a stricter margin: a lower crossover
    assert margins_of(pid, axis.mass, axis.damping, 1.5 * axis.crossover_hz, axis.delay_s,
                      loop.step).phase_margin_deg < 45.0 or axis.crossover_hz == tuning.high_hz
    # on the plant itself: stable, and tracking closer than the example's own 20 Hz loop
    axes = machine_axes(loop.machine)
    given, tuned = (tracking_metrics(simulate_config(replace(run, stop=2.0), progress=False),
                                     axes)["x"] for run in (loop, tuned_loop(loop, tuning)))
    assert tuned["einf"] < given["einf"] < 1e-3


def test_a_current_loops_lag_is_found_and_lowers_the_crossover():
    """The rough drive: the same 2 kg behind a 2 ms current loop (and friction, springs and
    ripple its rigid model leaves out): the lag is measured as delay, which costs phase, so
    the same margin gives a lower crossover than on the plain drive (50 Hz)."""
    tuning = tune_loop(load_run_config(EXAMPLES / "drive-rough.toml"), 40.0, seconds=3.0)
    (axis,) = tuning.axes
    assert axis.mass == pytest.approx(DRIVE.mass, rel=0.1)
    assert axis.delay_s == pytest.approx(0.002, abs=5e-4)
    assert axis.crossover_hz is not None and axis.crossover_hz < 25.0


def test_each_stage_axis_is_measured_alone_and_written_in_the_blocks_layout():
    loop = load_run_config(EXAMPLES / "stage.toml")
    tuning = tune_loop(loop, 40.0, seconds=3.0)
    masses = {a.axis: a.mass for a in tuning.axes}
    assert masses["x"] == pytest.approx(8.0, rel=0.1)  # beam and carriage
    assert masses["y"] == pytest.approx(2.0, rel=0.1)  # the carriage
    text = tuning_toml(tuning, "stage.toml")
    block = tomllib.loads(text)["fmu"]["pid"]
    assert block["builtin"] == "pid-gains" and block["effort_limit"] == {"x": 200.0, "y": 80.0}
    assert block["mass"] == masses
    assert set(block["crossover_hz"]) == {"x", "y"}
    for a in tuning.axes:
        assert a.margins is not None and a.margins.phase_margin_deg >= 40.0


@pytest.mark.parametrize("options, message", [({"phase_margin_deg": 95.0}, "phase margin"),
                                              ({"high_hz": 400.0}, "high_hz"),
                                              ({"seconds": 0.5}, "seconds")])
def test_a_bad_setting_is_refused_before_any_run(options, message):
    loop = load_run_config(EXAMPLES / "drive.toml")
    with pytest.raises(InputError, match=message):
        tune_loop(loop, **options)


def test_the_command_line_writes_the_proposal(tmp_path, capsys):
    from flexff.cli import main

    out = tmp_path / "tuned.toml"
    assert main(["tune", str(EXAMPLES / "drive.toml"), "-o", str(out), "--seconds", "2",
                 "--high-hz", "20"]) == 0
    shown = capsys.readouterr().out
    assert shown.splitlines()[0].split()[:3] == ["axis", "mass", "damping"]
    proposal = tomllib.loads(out.read_text())
    assert proposal["fmu"]["pid"]["axes"][0]["crossover_hz"] <= 20.0
    assert main(["tune", str(EXAMPLES / "drive.toml"), "-o", str(out),
                 "--phase-margin", "0"]) == 2
