"""Data collection on the first few trajectories of a set: the files and the manifest the
dataset loader reads, resuming an interrupted collection, atomic files, refusing foreign
folders, failures (a full disk stops it with one message), workers that end with a killed
collection, a Dask scheduler, the hardware set's 100 Hz files and `flexff data collect`.
The whole sim set runs in a slow test."""

import errno
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.run import simulate_config
from flexff.learning.collect import (
    CollectionError,
    CollectionReport,
    DataFolderError,
    Outcome,
    collect,
    dataset_signals,
    run_collection,
    trajectory_config,
)
from flexff.learning.dataset import (
    CURRENT_SIGNALS,
    MANIFEST,
    SIGNALS,
    DatasetError,
    load_dataset,
)
from flexff.learning.trajectories import trajectory_set
from flexff.plant.parameters import NOMINAL
from tests.helpers import assert_descendants_end_with

FIRST = 3  # trajectories of the small collections


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    """The first FIRST trajectories of the sim set, collected in one go."""
    return collect("sim", tmp_path_factory.mktemp("data") / "sim", progress=False, limit=FIRST)


def arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {name: data[name] for name in data.files}


def same_files(a: Path, b: Path, names) -> None:
    for name in names:
        x, y = arrays(a / f"{name}.npz"), arrays(b / f"{name}.npz")
        assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x), name


def names(k: int = FIRST) -> list[str]:
    return [t.name for t in trajectory_set("sim").trajectories[:k]]


def test_files_reload_bit_for_bit(collected):
    trajectories = trajectory_set("sim")
    for spec in trajectories.trajectories[:FIRST]:
        recorded = dataset_signals(simulate_config(trajectory_config(spec, trajectories)))
        saved = arrays(collected / f"{spec.name}.npz")
        assert list(saved) == [*SIGNALS, *CURRENT_SIGNALS]
        for name in saved:
            assert saved[name].dtype == np.float64 and saved[name].shape == (15001,)
            assert np.array_equal(saved[name], recorded[name]), (spec.name, name)
        # PID only: the applied force is the feedback force; ideal encoders in the nominal plant
        assert np.abs(saved["Fx"]).max() > 0.1 and np.ptp(saved["x"]) > 0.005
    assert sorted(p.name for p in collected.iterdir()) == sorted(
        [MANIFEST] + [f"{n}.npz" for n in names()])


def test_current_labels_are_what_the_plant_was_given(collected):
    """The dataset's i1..i3 are the plant's inputs: the motor torque the plant reports after
    each step is k_t times the current it was given for that step (no current reaches the
    limit on these trajectories)."""
    trajectories = trajectory_set("sim")
    spec = trajectories.trajectories[0]
    recording = simulate_config(trajectory_config(spec, trajectories))
    saved = arrays(collected / f"{spec.name}.npz")
    for k, name in enumerate(CURRENT_SIGNALS):
        assert np.abs(saved[name]).max() > 0.05
        assert np.allclose(recording[f"tau{k + 1}"][1:], NOMINAL.k_t[k] * saved[name][:-1],
                           rtol=1e-12, atol=1e-15)


def test_manifest(collected):
    manifest = json.loads((collected / MANIFEST).read_text())
    assert list(manifest) == ["format", "version", "set", "source", "sample_rate_hz", "plant",
                              "loop", "trajectories", "sha256"]
    loop = manifest["loop"]  # the set's own loop: PID on the nominal plant, FMUs by their hash
    assert loop["configuration"]["fmu"] == {
        "controller": {"builtin": "controller", "variant": "nominal", "encoders": 2},
        "plant": {"builtin": "plant", "variant": "nominal"}}
    assert loop["configuration"]["source"] == [{"kind": "constant",
                                                "values": {"Fx_ff": 0.0, "Fy_ff": 0.0}}]
    assert "reference" not in loop["configuration"] and "stop" not in loop["configuration"]["run"]
    assert {n: f["builtin"] for n, f in loop["fmus"].items()} == {"controller": "controller",
                                                                  "plant": "plant"}
    assert all(re.fullmatch("[0-9a-f]{64}", f["sha256"]) for f in loop["fmus"].values())
    assert (manifest["format"], manifest["version"], manifest["set"], manifest["source"],
            manifest["sample_rate_hz"]) == ("flexff-dataset", 3, "sim", "flexff data collect",
                                            1000)
    plant = manifest["plant"]
    assert plant["variant"] == "nominal"
    assert plant["parameters"]["i_max"] == 10.0 and plant["parameters"]["encoder_quantization"] == 0
    assert "x_start" not in plant["parameters"]
    specs = trajectory_set("sim").trajectories[:FIRST]
    assert manifest["trajectories"] == [
        {"name": s.name, "split": s.split, "file": f"{s.name}.npz", "reference": s.reference,
         "seed": s.seed,
         "sha256": hashlib.sha256((collected / f"{s.name}.npz").read_bytes()).hexdigest()}
        for s in specs]
    dataset = load_dataset(collected)  # the loader of the training side accepts it
    assert dataset.sample_rate_hz == 1000 and [t.name for t in dataset.trajectories] == names()


def test_resume_skips_what_is_there(collected, tmp_path):
    out = tmp_path / "sim"
    first = run_collection("sim", out, progress=False, limit=2)
    assert sorted(o.name for o in first.ran) == names(2)
    before = {n: os.stat(out / f"{n}.npz") for n in names(2)}
    time.sleep(0.01)
    second = run_collection("sim", out, progress=False, limit=FIRST)
    assert second.skipped == tuple(names(2)) and [o.name for o in second.ran] == names()[2:]
    for n, stat in before.items():  # not written again
        now = os.stat(out / f"{n}.npz")
        assert (now.st_ino, now.st_mtime_ns) == (stat.st_ino, stat.st_mtime_ns)
    # the same as a collection that was never interrupted
    same_files(out, collected, names())
    assert json.loads((out / MANIFEST).read_text()) == json.loads(
        (collected / MANIFEST).read_text())


def test_leftovers_of_an_interrupted_run(collected, tmp_path):
    out = tmp_path / "sim"
    out.mkdir()
    shutil.copy(collected / f"{names()[0]}.npz", out)
    stale = out / f".{names()[1]}.npz.k3j2_x.tmp"  # a temporary file a killed run left
    stale.write_bytes(b"PK\x03\x04 half a file")
    (out / f"{names()[1]}.npz").write_bytes(b"PK\x03\x04 truncated")  # not loadable: run again
    report = run_collection("sim", out, progress=False, limit=FIRST)
    assert report.skipped == (names()[0],) and sorted(o.name for o in report.ran) == names()[1:]
    assert not stale.exists() and not list(out.glob(".*"))
    same_files(out, collected, names())


def test_a_killed_collection_resumes(collected, tmp_path):
    """Kill a collection (and its worker) once its first file is there: what it left loads or
    is a hidden temporary file, there is no manifest, and running again completes it."""
    out = tmp_path / "sim"
    code = ("from flexff.learning.collect import run_collection; "
            f"run_collection('sim', {str(out)!r}, workers=1, progress=False, limit={FIRST})")
    process = subprocess.Popen([sys.executable, "-c", code], start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not list(out.glob("*.npz")) and process.poll() is None:
            assert time.monotonic() < deadline
            time.sleep(0.01)
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    left = list(out.glob("*.npz"))
    assert left and not (out / MANIFEST).exists()
    for path in left:
        assert list(arrays(path)) == [*SIGNALS, *CURRENT_SIGNALS]
    report = run_collection("sim", out, progress=False, limit=FIRST)
    assert len(report.skipped) == len(left) and report.ok
    same_files(out, collected, names())
    assert not list(out.glob(".*"))


@pytest.mark.parametrize("case, message", [
    ("other set", "holds set 'sim' in dataset version 3; this collects set 'hardware'"),
    ("other version", "holds set 'hardware' in dataset version 7"),
    ("not a dataset", "not a 'flexff-dataset' manifest"),
    ("foreign file", "no trajectories of set 'hardware' (notes.npz)"),
    ("other trajectory", "does not hold trajectory 'circle-00'"),
    ("a file", "exists and is not a folder"),
])
def test_foreign_folders_are_refused(collected, tmp_path, case, message):
    out = tmp_path / "data"
    out.mkdir()
    manifest = json.loads((collected / MANIFEST).read_text())
    if case == "other set":
        shutil.copytree(collected, out, dirs_exist_ok=True)
    elif case == "other version":
        (out / MANIFEST).write_text(json.dumps({**manifest, "set": "hardware", "version": 7}))
    elif case == "not a dataset":
        (out / MANIFEST).write_text('{"format": "something else"}')
    elif case == "foreign file":
        shutil.copy(collected / "circle-00.npz", out / "notes.npz")
    elif case == "other trajectory":  # a sim file where the hardware set has a namesake
        shutil.copy(collected / "circle-00.npz", out / "circle-00.npz")
    else:
        shutil.rmtree(out)
        out.write_text("")
    before = sorted(p.name for p in out.iterdir()) if out.is_dir() else None
    with pytest.raises(DataFolderError, match="^" + re.escape(str(out))) as info:
        run_collection("hardware", out, progress=False, limit=1)
    assert message in str(info.value)
    assert before == (sorted(p.name for p in out.iterdir()) if out.is_dir() else None)


def test_a_failed_trajectory_is_reported_and_the_others_finish(collected, tmp_path):
    out = tmp_path / "sim"
    blocker = out / f"{names()[1]}.npz"
    blocker.mkdir(parents=True)  # a folder where the file should go: its run cannot be saved
    report = run_collection("sim", out, progress=False, limit=FIRST)
    assert [o.name for o in report.failed] == [names()[1]] and not report.ok
    assert "IsADirectoryError" in report.failed[0].error and "\n" not in report.failed[0].error
    assert not report.failed[0].stops_all and not report.cancelled  # the others went on
    assert sorted(o.name for o in report.ran) == [names()[0], names()[2]]
    assert not (out / MANIFEST).exists()  # incomplete: no manifest
    with pytest.raises(CollectionError, match=f"1 of 3 trajectories.*\n{names()[1]}: "):
        collect("sim", out, progress=False, limit=FIRST)
    blocker.rmdir()
    retried = run_collection("sim", out, progress=False, limit=FIRST)
    assert [o.name for o in retried.ran] == [names()[1]] and len(retried.skipped) == 2
    same_files(out, collected, names())
    assert (out / MANIFEST).is_file()


def test_swapped_or_damaged_files_are_refused_and_collected_again(collected, tmp_path):
    """Files of a collected set swapped or truncated: training refuses them, naming the file and
    the command that repairs the folder; that command runs those trajectories again."""
    out = tmp_path / "sim"
    shutil.copytree(collected, out)
    first, second, third = (out / f"{n}.npz" for n in names())
    content = first.read_bytes()
    first.write_bytes(second.read_bytes())
    second.write_bytes(content)
    with pytest.raises(DatasetError, match=rf"{first} is not the file manifest.json lists.*run "
                                           rf"flexff data collect --set sim -o {out} again"):
        load_dataset(out)
    third.write_bytes(third.read_bytes()[:1000])
    report = run_collection("sim", out, progress=False, limit=FIRST)
    assert sorted(o.name for o in report.ran) == names() and report.ok
    same_files(out, collected, names())
    load_dataset(out)


def test_workers_must_be_at_least_one(tmp_path, capsys):
    from flexff.cli import main

    with pytest.raises(ValueError, match="workers must be at least 1, got 0"):
        run_collection("sim", tmp_path / "sim", workers=0, progress=False, limit=1)
    assert main(["data", "collect", "--set", "sim", "-o", str(tmp_path / "sim"),
                 "--workers", "0"]) == 2
    assert "workers must be at least 1" in capsys.readouterr().err
    assert not (tmp_path / "sim").exists()


def test_the_cli_refuses_fewer_than_one_draw(tmp_path, capsys):
    from flexff.cli import main

    assert main(["data", "collect", "--set", "sim", "-o", str(tmp_path / "sim"),
                 "--draws", "0"]) == 2
    assert "draws must be a whole number of at least 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "sim").exists()


def _full_disk(path, signals):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


@pytest.mark.parametrize("scheduler", [False, True], ids=["processes", "dask"])
def test_a_full_disk_stops_the_collection_with_one_message(tmp_path, monkeypatch, capsys,
                                                           scheduler):
    """Every file write fails with ENOSPC: the trajectories not yet started are cancelled, and
    `flexff data collect` says so in one line, without stack frames."""
    from flexff.cli import main

    # forked workers inherit it
    monkeypatch.setattr("flexff.learning.collect.save_signals", _full_disk)
    args = ["data", "collect", "--set", "sim", "-o", str(tmp_path / "sim"), "--workers", "1"]
    if scheduler:
        from dask.distributed import LocalCluster

        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                               dashboard_address=None)
        args = [*args[:-2], "--scheduler", cluster.scheduler_address]
    try:
        assert main(args) == 1
    finally:
        if scheduler:
            cluster.close()
    out, err = capsys.readouterr()
    full = [line for line in err.splitlines() if "No space left on device" in line]
    assert len(full) == 1 and full[0].startswith("stopped: OSError: [Errno 28]")
    failed, cancelled = (int(n) for n in re.search(r"\((\d+) failed with it.*; (\d+) not run\)",
                                                    full[0]).groups())
    assert failed >= 1 and cancelled >= 40 and failed + cancelled == 48
    assert "Traceback" not in err and 'File "' not in err and "FAILED" not in err
    assert f"{failed} failed, {cancelled} not run" in out
    assert not (tmp_path / "sim" / MANIFEST).exists()


def test_workers_end_with_a_killed_collection(tmp_path):
    """SIGKILL of `data collect` (the parent alone): its pool workers end within seconds
    instead of waiting forever for work."""
    code = ("from flexff.learning.collect import run_collection; "
            f"run_collection('sim', {str(tmp_path / 'sim')!r}, workers=2, progress=False, "
            f"limit=6)")
    process = subprocess.Popen([sys.executable, "-c", code], start_new_session=True)
    assert_descendants_end_with(process, lambda started: len(started) >= 2)  # forked workers


def test_on_a_dask_scheduler(collected, tmp_path):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        report = run_collection("sim", tmp_path / "sim", scheduler=cluster.scheduler_address,
                                progress=False, limit=2)
    assert report.ok and sorted(o.name for o in report.ran) == names(2)
    same_files(tmp_path / "sim", collected, names(2))


def test_hardware_files_keep_every_tenth_sample(tmp_path):
    trajectories = trajectory_set("hardware")
    spec = trajectories.trajectories[0]
    out = collect("hardware", tmp_path / "hw", progress=False, limit=1)
    saved = arrays(out / f"{spec.name}.npz")
    full = dataset_signals(simulate_config(trajectory_config(spec, trajectories)))
    assert saved["time"].shape == (10001,) and saved["time"][-1] == pytest.approx(100.0)
    np.testing.assert_allclose(np.diff(saved["time"]), 0.01, rtol=1e-9)
    for name in SIGNALS:
        assert np.array_equal(saved[name], full[name][::10]), name
    # the hardware plant counts whole encoder counts
    count = 2 * np.pi / 2048
    steps = np.diff(full["theta_s1"])
    steps = steps[steps != 0]
    np.testing.assert_allclose(steps / count, np.round(steps / count), atol=1e-6)
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["sample_rate_hz"] == 100 and manifest["plant"]["variant"] == "hardware"
    assert manifest["trajectories"][0]["seed"] == spec.seed


def test_cli_prints_a_summary_and_the_status(monkeypatch, tmp_path, capsys):
    from flexff.cli import main

    def fake(set_name, out, workers, scheduler, config, draws, progress):
        assert (set_name, workers, scheduler, config, draws, progress) == \
            ("hardware", 3, "tcp://h:8786", None, 2, True)
        return CollectionReport(Path(out), set_name, (Outcome("circle-01", 1.0, 7.25),),
                                ("circle-00",), (Outcome("circle-02", error="boom"),), 4.0)

    monkeypatch.setattr("flexff.learning.collect.run_collection", fake)
    status = main(["data", "collect", "--set", "hardware", "-o", str(tmp_path), "--workers", "3",
                   "--scheduler", "tcp://h:8786", "--draws", "2"])
    out, err = capsys.readouterr()
    assert status == 1
    assert "hardware: 3 trajectories" in out and "1 run, 1 skipped (already there), 1 failed" in out
    assert "7.25 A (circle-01)" in out and "circle-02: FAILED: boom" in err


def test_cli_refuses_a_foreign_folder(collected):
    result = subprocess.run([sys.executable, "-m", "flexff", "data", "collect", "--set",
                             "hardware", "-o", str(collected)], capture_output=True, text=True)
    assert result.returncode == 2 and "holds set 'sim'" in result.stderr


@pytest.mark.slow
def test_the_whole_sim_set(tmp_path):
    """The full sim collection (under a minute on 2 cores): every file, nothing saturated."""
    start = time.perf_counter()
    report = run_collection("sim", tmp_path / "sim", progress=False)
    seconds = time.perf_counter() - start
    assert report.ok and len(report.ran) == 48
    dataset = load_dataset(tmp_path / "sim")
    assert len(dataset.split("train")) == 44 and len(dataset.split("test")) == 4
    train = {t.name for t in dataset.split("train")}
    assert all(o.saturated == 0 and o.max_current < 9.5 for o in report.ran if o.name in train)
    print(f"sim collection: {seconds:.1f} s, largest current "
          f"{max(o.max_current for o in report.ran):.2f} A")
