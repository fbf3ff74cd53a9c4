"""`flexff data import --machine`: a drive's logs under any column names come back as the same
machine dataset as under the canonical ones, bit for bit; what they lack is derived and marked
so; every bad log or map is refused with one line naming file, key, column and row, and
nothing is written."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from flexff.cosim.machine import parse_machine
from flexff.cosim.memory import MemoryNeeded
from flexff.learning.log_files import LogError
from flexff.learning.machine_dataset import load_machine_dataset
from flexff.learning.machine_logs import import_machine_logs
from tests.helpers import matlab_v73_header

RATE = 1000.0
SAMPLES = 2000  # 2 s: two windows of the fast preset (learning.logs's shortest)
GAIN = 2.5  # the drive's effort per unit of its logged command `vir`
AXIS = {"name": "x", "measured": "plant.x", "feedforward": "pid.x_ff", "effort": "pid.x_effort",
        "range": [-0.05, 0.05], "velocity": 0.2, "acceleration": 2.0}
MAP = {"time": "t", "scalars": {"gain": GAIN},
       "columns": {"x_measured": "enc_pos", "x_effort": "gain * vir", "x_ref": "ref_pos"}}


def drive(log=None, axes=("x",)):
    """A description of a drive with `axes`, its logs read through the map `log`."""
    table = {"name": "drive", "axis": [{**AXIS, "name": n} for n in axes]}
    return parse_machine({**table, "log": log} if log is not None else table, "drive.toml")


def motion(seed: int, axis: str = "x") -> dict[str, np.ndarray]:
    """A drive's log in its own names: a sine position, the effort m a + c v + Coulomb
    friction as `vir` (the command before the gain), a lagging reference."""
    t = 3.0 + np.arange(SAMPLES) / RATE  # a logger's clock: not from zero
    w = 2 * np.pi * (0.5 + 0.1 * seed)
    x, v, a = 0.01 * np.sin(w * t), 0.01 * w * np.cos(w * t), -0.01 * w**2 * np.sin(w * t)
    effort = 2.0 * a + 5.0 * v + 0.3 * np.tanh(v / 1e-3)
    return {"t": t, f"{axis}_pos": x + 1e-6 * np.sin(7 * t), f"{axis}_vir": effort / GAIN,
            f"{axis}_ref": x}


def renamed(values):
    return {"t": values["t"], "enc_pos": values["x_pos"], "vir": values["x_vir"],
            "ref_pos": values["x_ref"]}


def canonical(values):
    return {"time": values["t"], "x_measured": values["x_pos"],
            "x_effort": GAIN * values["x_vir"], "x_ref": values["x_ref"]}


def write_log(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """`columns` as a CSV (17 significant digits: exact) or MATLAB v5 log."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".csv":
        np.savetxt(path, np.column_stack(list(columns.values())), fmt="%.17g", delimiter=",",
                   header=",".join(columns), comments="")
    else:
        savemat(path, columns)
    return path


def logs(folder: Path, shape, suffix=".csv", runs=("run-a", "run-b")) -> list[Path]:
    return [write_log(folder / f"{name}{suffix}", shape(motion(k))) for k, name in
            enumerate(runs)]


def arrays(folder: Path) -> dict[str, dict[str, np.ndarray]]:
    return {t.name: dict(t.signals) for t in load_machine_dataset(folder).trajectories}


def test_renamed_columns_and_a_gain_give_the_canonical_dataset(tmp_path):
    ours = import_machine_logs(logs(tmp_path / "own", canonical), tmp_path / "a", drive())
    theirs = import_machine_logs(logs(tmp_path / "mapped", renamed), tmp_path / "b",
                                 drive(MAP))
    assert ours.signals == ("time", "x_ref", "vx_ref", "ax_ref", "jx_ref", "x_measured",
                            "x_effort")
    a, b = arrays(ours.path), arrays(theirs.path)
    assert list(a) == list(b) == ["run-a", "run-b"]
    for name in a:
        assert set(a[name]) == set(ours.signals)
        for signal in ours.signals:
            assert np.array_equal(a[name][signal], b[name][signal]), (name, signal)
    assert [t.derived for t in ours.trajectories] == [t.derived for t in theirs.trajectories]
    assert [t.split for t in theirs.trajectories] == ["train", "test"]
    np.testing.assert_allclose(a["run-a"]["time"], np.arange(SAMPLES) / RATE, atol=1e-12)
    entry = json.loads((theirs.path / "manifest.json").read_text())["trajectories"][0]
    assert entry["log"]["signals"]["x_effort"] == "gain * vir"
    assert entry["log"]["start_s"] == 3.0 and entry["log"]["resampled"] == "kept"


def test_a_matlab_log_gives_what_its_csv_gives(tmp_path):
    csv = import_machine_logs(logs(tmp_path / "csv", renamed), tmp_path / "a", drive(MAP))
    mat = import_machine_logs(logs(tmp_path / "mat", renamed, ".mat"), tmp_path / "b",
                              drive(MAP))
    a, b = arrays(csv.path), arrays(mat.path)
    assert all(np.array_equal(a[n][s], b[n][s]) for n in a for s in csv.signals)
    manifest = json.loads((mat.path / "manifest.json").read_text())
    assert manifest["trajectories"][0]["log"]["format"] == "MATLAB v5/v7"


def test_a_matlab_v73_log(tmp_path):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "logs" / "run-a.mat"
    path.parent.mkdir()
    with h5py.File(path, "w", userblock_size=512) as handle:  # MATLAB's layout: 1 x n
        for name, values in renamed(motion(0)).items():
            handle.create_dataset(name, data=values[None, :])
            handle[name].attrs["MATLAB_class"] = np.bytes_("double")
    matlab_v73_header(path)
    csv = write_log(tmp_path / "logs" / "run-b.csv", renamed(motion(1)))
    v73 = import_machine_logs([path, csv], tmp_path / "v73", drive(MAP))
    plain = import_machine_logs(logs(tmp_path / "csv", renamed), tmp_path / "csv-data",
                                drive(MAP))
    a, b = arrays(v73.path), arrays(plain.path)
    assert all(np.array_equal(a[n][s], b[n][s]) for n in a for s in v73.signals)


def test_a_rate_keeps_every_nth_sample(tmp_path):
    full = import_machine_logs(logs(tmp_path / "logs", renamed), tmp_path / "1000", drive(MAP))
    tenth = import_machine_logs(logs(tmp_path / "logs", renamed), tmp_path / "100", drive(MAP),
                                rate_hz=100.0)
    assert tenth.sample_rate_hz == 100.0
    a, b = full.trajectories[0].signals, tenth.trajectories[0].signals
    for signal in ("time", "x_ref", "x_measured", "x_effort"):
        assert np.array_equal(a[signal][::10], b[signal]), signal


def test_a_rate_beyond_memory_is_refused_before_it_is_allocated(tmp_path):
    files = logs(tmp_path / "logs", renamed)
    with pytest.raises(MemoryNeeded, match=rf"^{files[0]}: its 1.999 s at 1e\+12 Hz \(--rate\) "
                                           rf"needs [\d,]+ MB, more than the [\d,]+ MB"):
        import_machine_logs(files, tmp_path / "data", drive(MAP), rate_hz=1e12)
    assert not (tmp_path / "data").exists()


def test_a_missing_reference_is_derived_and_marked(tmp_path):
    """No reference in the logs, none mapped: the measured position stands in, its
    derivatives are Savitzky-Golay's, and the manifest says so."""
    shape = {"time": "t", "scalars": {"gain": GAIN},
             "columns": {"x_measured": "enc_pos", "x_effort": "gain * vir"}}
    dataset = import_machine_logs(logs(tmp_path / "logs", renamed), tmp_path / "data",
                                  drive(shape))
    traj = dataset.trajectories[0]
    assert traj.derived["x_ref"] == "the measured position x_measured (the log has no x_ref)"
    assert traj.derived["vx_ref"].startswith("first derivative of the derived x_ref (cubic "
                                             "Savitzky-Golay")
    assert set(traj.derived) == {"x_ref", "vx_ref", "ax_ref", "jx_ref"}
    assert np.array_equal(traj.signals["x_ref"], traj.signals["x_measured"])
    w, t = 2 * np.pi * 0.5, 3.0 + traj.signals["time"]
    inner = slice(50, -50)  # the filter's edges aside
    np.testing.assert_allclose(traj.signals["vx_ref"][inner], 0.01 * w * np.cos(w * t)[inner],
                               atol=2e-5)


def test_three_axes(tmp_path):
    """A 3-axis description: every axis's signals, each axis's map; a 1-axis log lacks the
    others' columns."""
    axes = ("q1", "q2", "z")
    columns = {}
    for n in axes:
        columns |= {f"{n}_measured": f"{n}_pos", f"{n}_effort": f"gain * {n}_vir"}
    three = drive({"time": "t", "scalars": {"gain": GAIN}, "columns": columns}, axes)

    def shape(values):  # axis j moves (j + 1) times as far as the drive
        return {"t": values["t"], **{f"{n}_{c}": values[f"x_{c}"] * (j + 1)
                                      for j, n in enumerate(axes) for c in ("pos", "vir")}}

    dataset = import_machine_logs(logs(tmp_path / "logs", shape), tmp_path / "data", three)
    manifest = json.loads((dataset.path / "manifest.json").read_text())
    assert [a["name"] for a in manifest["machine"]["axes"]] == list(axes)
    assert dataset.signals[-6:] == ("q1_measured", "q2_measured", "z_measured", "q1_effort",
                                    "q2_effort", "z_effort")
    traj = dataset.trajectories[0]
    np.testing.assert_array_equal(traj.signals["z_effort"], GAIN * (3 * motion(0)["x_vir"]))
    with pytest.raises(LogError, match=r"run-a\.csv: missing column q2_pos, which "
                                       r"machine\.log\.columns\.q2_measured = 'q2_pos' reads"):
        import_machine_logs(logs(tmp_path / "one", renamed), tmp_path / "other",
                            drive({"time": "t", "scalars": {"gain": GAIN}, "columns": {
                                **columns, "q1_measured": "enc_pos", "q1_effort": "gain * vir"}},
                                axes))


def test_a_time_column_of_another_name(tmp_path):
    """`time` names the log's clock; a column the log calls `time` is then not read."""
    def shape(values):
        return {"time": np.zeros(SAMPLES), **renamed(values)}

    dataset = import_machine_logs(logs(tmp_path / "logs", shape), tmp_path / "data", drive(MAP))
    np.testing.assert_allclose(np.diff(dataset.trajectories[0].signals["time"]), 1 / RATE)


# -- errors -----------------------------------------------------------------------------------
def _broken(case: str, folder: Path) -> tuple[list[Path], dict, str]:
    """The logs, the map and the expected message of an error case."""
    a, b = renamed(motion(0)), renamed(motion(1))
    first = folder / "run-a.csv"
    shape = MAP
    if case == "missing column":
        del a["vir"]
        message = (f"{first}: missing column vir, which machine.log.columns.x_effort = "
                   f"'gain * vir' reads")
    elif case == "missing own column":
        shape = {**MAP, "columns": {"x_effort": "gain * vir"}}
        message = (f"{first}: missing column x_measured: a log holds each measured position "
                   f"and effort as the column of its name, or [machine.log.columns] maps it")
    elif case == "NaN":
        a["enc_pos"] = a["enc_pos"].copy()
        a["enc_pos"][17] = np.nan
        message = f"{first}: column enc_pos, data row 18 (line 19): NaN or Inf"
    elif case == "NaN of an expression":
        a["vir"] = a["vir"] - a["vir"][40]  # sqrt of a negative from row 41 or 42 on
        shape = {**MAP, "columns": {**MAP["columns"], "x_effort": "sqrt(vir) * gain"}}
        row = int(np.flatnonzero(a["vir"] < 0)[0])
        message = (f"{first}: machine.log.columns.x_effort = 'sqrt(vir) * gain', data row "
                   f"{row + 1} (line {row + 2}): NaN or Inf")
    elif case == "time not increasing":
        a["t"] = a["t"].copy()
        a["t"][100] = a["t"][99]
        message = f"{first}: column t, data row 101 (line 102): time does not increase"
    elif case == "missing time":
        a["clock"] = a.pop("t")
        message = f"{first}: missing column(s) t: the header row must name t"
    elif case in ("semicolons", "tabs"):  # as a spreadsheet in many locales saves CSV
        write_log(first, a)
        first.write_text(first.read_text().replace(",", {"semicolons": ";", "tabs": "\t"}[case]))
        message = (f"{first}: missing column(s) t: the header row must name t (optionally "
                   f"ax_ref, enc_pos, jx_ref, ref_pos, vir, vx_ref); the header row is one "
                   f"column that holds {case}: "
                   f"save the table with commas between the columns and points as decimal "
                   f"marks")
        return [first, write_log(folder / "run-b.csv", b)], shape, message
    else:
        assert case == "too short"
        a = {n: v[:999] for n, v in a.items()}
        message = f"{first}: column time: 999 samples at 1000 Hz, fewer than one training window"
    return [write_log(first, a), write_log(folder / "run-b.csv", b)], shape, message


@pytest.mark.parametrize("case", ["missing column", "missing own column", "NaN",
                                  "NaN of an expression", "time not increasing", "missing time",
                                  "semicolons", "tabs", "too short"])
def test_a_bad_log_is_refused_naming_file_column_and_row(tmp_path, case):
    files, shape, message = _broken(case, tmp_path / "logs")
    with pytest.raises(LogError) as error:
        import_machine_logs(files, tmp_path / "data", drive(shape))
    assert str(error.value).startswith(message), str(error.value)
    assert "\n" not in str(error.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs"]  # nothing written


def test_the_command_line_takes_a_description_file(tmp_path, capsys):
    from flexff.cli import main

    description = tmp_path / "drive.toml"
    description.write_text(
        '[machine]\nname = "drive"\n[[machine.axis]]\nname = "x"\nmeasured = "plant.x"\n'
        'feedforward = "pid.x_ff"\neffort = "pid.x_effort"\nrange = [-0.05, 0.05]\n'
        'velocity = 0.2\nacceleration = 2.0\n[machine.log]\ntime = "t"\n'
        'scalars = { gain = 2.5 }\n[machine.log.columns]\nx_measured = "enc_pos"\n'
        'x_effort = "gain * vir"\n')
    files = [str(p) for p in logs(tmp_path / "logs", renamed)]
    out = tmp_path / "data"
    assert main(["data", "import", *files, "-o", str(out), "--machine", str(description),
                 "--test", "run-a"]) == 0
    printed = capsys.readouterr().out
    assert "run-b (train): 2000 samples; derived, not measured: x_ref, vx_ref" in printed
    assert f"2 logs -> {out} at 1000 Hz (test split: run-a)" in printed
    assert load_machine_dataset(out, drive()).split("test")[0].name == "run-a"
    no_vir = tmp_path / "bad" / "run-a.csv"
    write_log(no_vir, {k: v for k, v in renamed(motion(0)).items() if k != "vir"})
    assert main(["data", "import", str(no_vir), files[1], "-o", str(tmp_path / "other"),
                 "--machine", str(description)]) == 2
    assert capsys.readouterr().err == (f"flexff: error: {no_vir}: missing column vir, which "
                                       f"machine.log.columns.x_effort = 'gain * vir' reads\n")
    assert not (tmp_path / "other").exists()
