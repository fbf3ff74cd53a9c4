"""Metrics against hand-computed values, the recording's round trip and atomic writes, plots."""

import math
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from flexff.cosim.metrics import error_norms, named_axes, run_metrics, tracking_metrics
from flexff.cosim.plots import write_plots
from flexff.cosim.recording import (
    CSV_NAME,
    NPZ_NAME,
    PARQUET_NAME,
    PARTS_NAME,
    Recording,
    atomic_write,
    load_recording,
    save_recording,
)
from flexff.fmu.errors import InputError

XY = named_axes(("x", "y"))


def synthetic():
    """Four points 0.5 s apart: e_x = (0, 1, -2, 2) mm, e_y = (3, 3, 3, 3) mm."""
    time = np.array([0.0, 0.5, 1.0, 1.5])
    x_ref = np.array([0.010, 0.011, 0.012, 0.013])
    y_ref = np.array([-0.02, -0.01, 0.0, 0.01])
    signals = {"x_ref": x_ref, "y_ref": y_ref,
               "x": x_ref - np.array([0.0, 1e-3, -2e-3, 2e-3]), "y": y_ref - 3e-3}
    return Recording(time, signals, wall_s=0.25)


def test_metrics_by_hand():
    m = tracking_metrics(synthetic(), XY)
    # e_x: sum e^2 = (0 + 1 + 4 + 4) mm^2 = 9e-6 m^2, dt = 0.5 s, T = 1.5 s
    assert m["x"]["e2"] == pytest.approx(math.sqrt(9e-6 * 0.5) / 1.5, rel=1e-12)
    assert m["x"]["einf"] == pytest.approx(2e-3, rel=1e-12)
    assert m["x"]["rms"] == pytest.approx(1.5e-3, rel=1e-12)
    # e_y: constant 3 mm
    assert m["y"]["e2"] == pytest.approx(math.sqrt(4 * 9e-6 * 0.5) / 1.5, rel=1e-12)
    assert m["y"]["einf"] == pytest.approx(3e-3, rel=1e-12)
    assert m["y"]["rms"] == pytest.approx(3e-3, rel=1e-12)
    full = run_metrics(synthetic(), XY)
    assert list(full) == ["x", "y", "wall_s", "real_time_factor"]
    assert full["real_time_factor"] == pytest.approx(1.5 / 0.25)
    with pytest.raises(ValueError, match="two samples"):
        error_norms(np.zeros(1), 1e-3)


def test_recording_round_trip_is_bit_exact(tmp_path, rng, monkeypatch):
    monkeypatch.setattr("flexff.cosim.recording.CHUNK_BYTES", 300 * 8 * 5)  # four chunks
    time = np.arange(1001) * 1e-3
    signals = {name: rng.standard_normal(1001) * 10.0 ** rng.integers(-12, 3)
               for name in ("x_ref", "theta_s1", "i1", "Fx_ff")}
    signals["i1"][5] = np.nextafter(0.0, 1.0)  # a subnormal survives too
    paths = save_recording(Recording(time, signals), tmp_path, csv=True)
    assert [p.name for p in paths] == [PARQUET_NAME, CSV_NAME]
    assert not (tmp_path / PARTS_NAME).exists()
    back = load_recording(tmp_path)
    assert list(back.signals) == list(signals)
    assert back.time.tobytes() == time.tobytes()
    for name, values in signals.items():
        assert back[name].dtype == np.float64 and back[name].tobytes() == values.tobytes()
    table = np.loadtxt(tmp_path / CSV_NAME, delimiter=",", skiprows=1)
    header = (tmp_path / CSV_NAME).read_text().splitlines()[0]
    assert header == "time,x_ref,theta_s1,i1,Fx_ff"
    assert np.array_equal(table, np.column_stack([time, *signals.values()]))


def test_records_of_earlier_versions_still_load(tmp_path):
    time = np.arange(5) * 0.1
    with open(tmp_path / NPZ_NAME, "wb") as handle:
        np.savez(handle, time=time, x=time**2)
    back = load_recording(tmp_path)
    assert back.time.tobytes() == time.tobytes() and back["x"].tobytes() == (time**2).tobytes()


def test_typed_columns_round_trip(tmp_path):
    time = np.arange(3) * 1.0
    signals = {"n": np.array([1, -2, 3], dtype=np.int32), "b": np.array([True, False, True]),
               "s": np.array(["a", "", "ccc"])}
    save_recording(Recording(time, signals), tmp_path)
    back = load_recording(tmp_path)
    for name, values in signals.items():
        assert back[name].dtype == values.dtype and np.array_equal(back[name], values)


def test_a_folder_without_a_record_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no record"):
        load_recording(tmp_path)


def test_an_interrupted_write_leaves_no_file(tmp_path):
    target = tmp_path / "signals.npz"

    def half_write(tmp):
        tmp.write_bytes(b"half a file")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, half_write)
    assert list(tmp_path.iterdir()) == []
    target.write_bytes(b"old")
    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, half_write)
    assert target.read_bytes() == b"old"  # the previous file is untouched
    assert [p.name for p in tmp_path.iterdir()] == ["signals.npz"]


def test_recording_checks_its_shape():
    with pytest.raises(ValueError, match="has \\(3,\\) samples"):
        Recording(np.arange(4.0), {"x": np.zeros(3)})
    with pytest.raises(ValueError, match="reserved"):
        Recording(np.arange(4.0), {"time": np.zeros(4)})


def test_plots_are_written(tmp_path):
    t = np.arange(2001) * 1e-3
    angle = 2 * np.pi * t / 2.0
    signals = {"x_ref": 0.01 * np.cos(angle), "y_ref": 0.01 * np.sin(angle),
               "x": 0.009 * np.cos(angle - 0.1), "y": 0.009 * np.sin(angle - 0.1),
               "Fx": np.sin(angle), "Fy": np.cos(angle),
               "Fx_ff": 0.5 * np.sin(3 * angle), "Fy_ff": np.zeros_like(t)}
    assert [p.name for p in write_plots(Recording(t, signals), tmp_path, XY)] == [
        "path.png", "error.png"]  # no efforts named: no forces.png
    loop = [replace(a, unit="m", feedforward=f"F{a.name}_ff", effort=f"F{a.name}",
                    effort_unit="N") for a in XY]
    paths = write_plots(Recording(t, signals), tmp_path, loop)
    assert [p.name for p in paths] == ["path.png", "error.png", "forces.png"]
    assert [p.name for p in write_plots(Recording(t, signals), tmp_path / "one", loop[:1])] \
        == ["error.png", "forces.png"]  # a path needs two axes
    for path in paths:
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


@pytest.mark.learn
def test_importing_flexff_leaves_matplotlib_backend_alone():
    """A notebook's backend stays what it was: flexff draws on Figure objects, never pyplot."""
    code = ("import matplotlib; import flexff.cosim.run, flexff.learning.report, "
            "flexff.learning.train; print(matplotlib.get_backend())")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "MPLBACKEND": "svg"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "svg"
