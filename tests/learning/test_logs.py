"""`flexff data import`: collected runs written as CSV and MATLAB logs come back as the same
dataset on every measured signal, bit for bit; what the logs lack is derived and marked so,
and training never reads it; every bad log is refused with one line naming file, column and
row, and nothing is written."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from flexff.learning.collect import collect
from flexff.learning.dataset import (
    ENCODER_SIGNALS,
    LABEL_SIGNALS,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
    DatasetError,
    Trajectory,
    load_dataset,
    write_manifest,
)
from flexff.learning.features import prepare_trajectory
from flexff.learning.logs import FK, import_logs
from flexff.learning.manipulator_settings import manipulator_settings
from flexff.learning.train import train
from tests.helpers import matlab_v73_header

MEASURED = ("time", *ENCODER_SIGNALS, *LABEL_SIGNALS)
FIRST = 3  # collected trajectories


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    return collect("sim", tmp_path_factory.mktemp("logs") / "sim", progress=False, limit=FIRST)


def signals(folder: Path) -> dict[str, dict[str, np.ndarray]]:
    return {t.name: dict(t.signals) for t in load_dataset(folder).trajectories}


def write_log(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """`columns` as a CSV (17 significant digits: exact) or MATLAB v5 log."""
    if path.suffix == ".csv":
        np.savetxt(path, np.column_stack(list(columns.values())), fmt="%.17g", delimiter=",",
                   header=",".join(columns), comments="")
    else:
        savemat(path, columns)
    return path


def logs(collected: Path, folder: Path, suffix: str, rows: int | None = None) -> list[Path]:
    """The collected runs as logs: the first with its reference, the others without."""
    folder.mkdir(exist_ok=True)
    files = []
    for k, (name, values) in enumerate(signals(collected).items()):
        names = MEASURED + (REFERENCE_SIGNALS if k == 0 else ())
        files.append(write_log(folder / f"{name}{suffix}", {n: values[n][:rows] for n in names}))
    return files


@pytest.fixture(scope="module", params=[".csv", ".mat"])
def imported(request, collected, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("imported")
    import_logs(logs(collected, folder / "logs", request.param), folder / "data")
    return folder / "data"


def test_measured_signals_come_back_bit_for_bit(collected, imported):
    ours, theirs = signals(collected), signals(imported)
    assert list(ours) == list(theirs)
    for k, name in enumerate(ours):
        given = MEASURED + (REFERENCE_SIGNALS if k == 0 else ())
        for signal in given:
            assert np.array_equal(ours[name][signal], theirs[name][signal]), (name, signal)
        # the true position from the ideal encoders: forward kinematics to float rounding
        for axis in POSITION_SIGNALS:
            np.testing.assert_allclose(theirs[name][axis], ours[name][axis], rtol=0, atol=1e-12)


def test_derived_signals_are_marked(collected, imported):
    manifest = json.loads((imported / "manifest.json").read_text())
    assert (manifest["set"], manifest["source"], manifest["sample_rate_hz"]) == (
        "hardware", "flexff data import", 1000.0)
    entries = manifest["trajectories"]
    assert [e["split"] for e in entries] == ["train", "train", "test"]  # the last log: test
    assert entries[0]["derived"] == {"x": FK, "y": FK}
    assert set(entries[1]["derived"]) == {*POSITION_SIGNALS, *REFERENCE_SIGNALS}
    assert entries[1]["derived"]["vx_ref"].startswith("first derivative of the derived x_ref")
    assert entries[1]["log"]["resampled"] == "kept" and entries[1]["log"]["samples"] == 15001
    assert all(t.derived == e["derived"] for t, e in zip(load_dataset(imported).trajectories,
                                                         entries))


def test_training_reads_no_derived_signal(imported):
    """Every preset's preprocessing gives the same features and labels with the derived
    signals replaced by NaN; and a manifest that marks a trained signal derived is refused."""
    dataset = load_dataset(imported)
    for preset in ("fast", "thesis"):
        features = manipulator_settings("pgnn", preset)[1]
        for traj in dataset.trajectories:
            blind = Trajectory(traj.name, traj.split, {
                n: np.full_like(v, np.nan) if n in traj.derived else v
                for n, v in traj.signals.items()})
            for a, b in zip(prepare_trajectory(traj, dataset.sample_rate_hz, features,
                                               np.random.default_rng(1)),
                            prepare_trajectory(blind, dataset.sample_rate_hz, features,
                                               np.random.default_rng(1))):
                assert np.array_equal(a, b)
    manifest = json.loads((imported / "manifest.json").read_text())
    entries = [{k: v for k, v in e.items() if k != "sha256"} for e in manifest["trajectories"]]
    entries[0]["derived"] = {"Fx": "made up"}
    with pytest.raises(DatasetError, match="trajectory 'circle-00': Fx marked derived, but "
                                           "training reads them as measured"):
        write_manifest(imported, "hardware", 1000.0, {}, entries, "flexff data import")


def test_a_damaged_import_says_to_import_again(imported, tmp_path):
    damaged = tmp_path / "data"
    shutil.copytree(imported, damaged)
    (damaged / "circle-01.npz").unlink()
    with pytest.raises(DatasetError, match=r"circle-01.npz is listed in manifest.json but "
                                           "missing; import the logs again"):
        load_dataset(damaged)


def test_one_epoch_of_training(imported, tmp_path):
    metrics = train("pgnn", "fast", imported, tmp_path / "run", progress=False, epochs=1)
    assert np.isfinite(metrics["test_mse"]) and metrics["model_rate_hz"] == 100.0


def test_rates(collected, tmp_path):
    """--rate 100 keeps every 10th sample of 1 kHz logs; a log with jittered sample times is
    interpolated onto a uniform grid."""
    files = logs(collected, tmp_path / "logs", ".csv")
    decimated = signals(import_logs(files, tmp_path / "100", rate_hz=100.0).path)
    for name, values in signals(collected).items():
        for signal in MEASURED:
            assert np.array_equal(decimated[name][signal], values[signal][::10])
    rng = np.random.default_rng(5)
    values = {n: v[:3000] for n, v in signals(collected)["circle-00"].items()}
    values["time"] = 1.7e4 + values["time"] + 2e-6 * rng.uniform(-1, 1, 3000)  # 0.2 % jitter
    values["Fx"] = 0.5 + 2.0 * values["time"]  # linear: interpolated exactly
    jittered = write_log(tmp_path / "jittered.csv", {n: values[n] for n in MEASURED})
    dataset = import_logs([jittered, files[1]], tmp_path / "jitter", test=["jittered"])
    traj = dataset.trajectories[0]
    np.testing.assert_allclose(np.diff(traj.signals["time"]), 1e-3, rtol=1e-9)
    manifest = json.loads((dataset.path / "manifest.json").read_text())
    log = manifest["trajectories"][0]["log"]
    assert log["resampled"].startswith("interpolated linearly") and log["start_s"] == values[
        "time"][0]
    np.testing.assert_allclose(traj.signals["Fx"], 0.5 + 2.0 * (traj.signals["time"] +
                                                                log["start_s"]), rtol=1e-9)
    assert [t.split for t in dataset.trajectories] == ["test", "train"]


def test_matlab_v73_with_h5py(collected, tmp_path):
    h5py = pytest.importorskip("h5py")
    files = logs(collected, tmp_path / "logs", ".csv")
    path = tmp_path / "logs" / "circle-00-v73.mat"
    values = signals(collected)["circle-00"]
    with h5py.File(path, "w", userblock_size=512) as handle:  # MATLAB's layout: n x 1 -> 1 x n
        for name in MEASURED:
            handle.create_dataset(name, data=values[name][None, :])
            handle[name].attrs["MATLAB_class"] = np.bytes_("double")
    matlab_v73_header(path)
    dataset = import_logs([path, files[1]], tmp_path / "data")
    assert all(np.array_equal(dataset.trajectories[0].signals[n], values[n]) for n in MEASURED)


# -- errors -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def base(collected) -> dict[str, dict[str, np.ndarray]]:
    """Two logs of 2 s at 1 kHz: two windows of the fast preset."""
    return {name: {n: v[:2000] for n, v in values.items() if n in MEASURED}
            for name, values in list(signals(collected).items())[:2]}


def _case(case: str, base: dict, folder: Path, monkeypatch) -> tuple[list, str]:
    """The command line arguments and the expected message of an error case."""
    a, b = (dict(v) for v in base.values())
    first, second = folder / "a.csv", folder / "b.csv"
    extra, message = [], ""
    if case == "missing column":
        del a["Fy"]
        message = f"{first}: missing column(s) Fy: the header row must name time, theta_s1"
    elif case == "NaN":
        a["Fx"] = a["Fx"].copy()
        a["Fx"][17] = np.nan
        message = f"{first}: column Fx, data row 18 (line 19): NaN or Inf"
    elif case == "Inf":
        b["theta_s2"] = b["theta_s2"].copy()
        b["theta_s2"][5] = -np.inf
        message = f"{second}: column theta_s2, data row 6 (line 7): NaN or Inf"
    elif case == "time not increasing":
        a["time"] = a["time"].copy()
        a["time"][100] = a["time"][99]
        message = (f"{first}: column time, data row 101 (line 102): time does not increase "
                   f"(t = 0.099 s, then 0.099 s)")
    elif case == "rate varies":
        a["time"] = a["time"] + np.where(np.arange(2000) >= 500, 5e-4, 0.0)
        message = (f"{first}: column time, data row 501 (line 502): a sample interval of "
                   f"0.0015 s, more than 1 % off the log's 0.001 s")
    elif case == "too short":
        b = {n: v[:999] for n, v in b.items()}
        message = (f"{second}: column time: 999 samples at 1000 Hz, fewer than one training "
                   f"window (1000 samples, 1 s)")
    elif case == "rates differ":
        b = {n: v[::2] for n, v in b.items()}
        message = (f"{second}: column time: sampled at 500 Hz, {first} at 1000 Hz: give --rate "
                   f"HZ to resample them to one rate")
    elif case == "no wrist position":
        a["theta_s1"] = a["theta_s1"] + 3.0
        message = f"{first}: columns theta_s1..3, data row 1 (after resampling): no wrist position"
    elif case == "unknown --test":
        extra, message = ["--test", "c"], "--test: no log named c (the logs: a, b)"
    elif case == "empty --test":
        extra, message = ["--test", ","], "--test names no log"
    elif case == "every log --test":
        extra, message = ["--test", "a,b"], "--test names every log: leave at least one"
    elif case == "one log":
        second = None
        message = "one log: training needs at least one log for training and one for the test"
    elif case == "not a number":
        write_log(first, a)
        lines = first.read_text().splitlines()
        cells = lines[3].split(",")
        cells[5] = "abc"
        lines[3] = ",".join(cells)
        first.write_text("\n".join(lines) + "\n")
        message = f"{first}: column Fy, data row 3 (line 4): not a number"
        return [first, write_log(second, b)], message
    elif case == "cells":
        write_log(first, a)
        lines = first.read_text().splitlines()
        lines[10] = ",".join(lines[10].split(",")[:5])
        first.write_text("\n".join(lines) + "\n")
        message = f"{first}: data row 10 (line 11) has 5 cells, the header 6"
        return [first, write_log(second, b)], message
    elif case.startswith("mat"):
        first = folder / "a.mat"
        if case == "mat matrix":
            a["theta_s1"] = np.column_stack([a["theta_s1"], a["theta_s1"]])
            message = (f"{first}: variable theta_s1 is not a real vector (a float64 array of "
                       f"shape (2000, 2))")
        elif case == "mat lengths":
            a["Fy"] = a["Fy"][:1500]
            message = f"{first}: column Fy has 1500 rows, time 2000"
        elif case == "mat v7.3 without h5py":
            first.write_bytes(bytes(1024))
            matlab_v73_header(first)
            monkeypatch.setitem(sys.modules, "h5py", None)  # as if it were not installed
            return [first, write_log(second, b)], (f"{first}: this is a MATLAB v7.3 file: install "
                                                   f"h5py (pip install 'flexff[matlab]')")
        else:
            first.write_bytes(b"MATLAB? no: just text\n" * 10)
            return [first, write_log(second, b)], f"{first}: not a MATLAB .mat file"
        savemat(first, a)
        return [first, write_log(second, b)], message
    elif case == "same name":
        second = folder / "sub" / "a.csv"
        second.parent.mkdir()
        message = f"{first} and {second} have the same name 'a': rename one"
    elif case == "missing file":
        missing = folder / "nothing.csv"
        return [missing, write_log(second, b)], f"{missing}: no such log file"
    files = [write_log(first, a)] + ([write_log(second, b)] if second else [])
    return files + extra, message


CASES = ["missing column", "NaN", "Inf", "time not increasing", "rate varies", "too short",
         "rates differ", "no wrist position", "unknown --test", "empty --test", "every log --test",
         "one log",
         "not a number", "cells", "mat matrix", "mat lengths", "mat v7.3 without h5py",
         "mat not a mat file", "same name", "missing file"]


@pytest.mark.parametrize("case", CASES)
def test_every_bad_log_is_refused_with_one_line(base, tmp_path, capsys, monkeypatch, case):
    from flexff.cli import main

    folder = tmp_path / "logs"
    folder.mkdir()
    args, message = _case(case, base, folder, monkeypatch)
    out = tmp_path / "data"
    assert main(["data", "import", *map(str, args), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"flexff: error: {message}"), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs"]  # nothing written


def test_an_output_folder_that_holds_files_is_refused(base, tmp_path, capsys):
    from flexff.cli import main

    files = [write_log(tmp_path / f"{name}.csv", values) for name, values in base.items()]
    out = tmp_path / "data"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["data", "import", *map(str, files), "-o", str(out)]) == 2
    assert capsys.readouterr().err == (f"flexff: error: {out} exists and is not an empty folder: "
                                       f"import into a new folder\n")
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    out.joinpath("notes.txt").unlink()  # an empty folder is taken
    assert main(["data", "import", *map(str, files), "-o", str(out), "--test", "circle-00"]) == 0
    printed = capsys.readouterr().out
    assert f"2 logs -> {out} at 1000 Hz (test split: circle-00)" in printed
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
