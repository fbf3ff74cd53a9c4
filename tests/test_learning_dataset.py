"""The dataset format: what is written is read back; every kind of bad folder is refused."""

import json

import numpy as np
import pytest

from learning.dataset import SIGNALS, DatasetError, load_dataset
from learning.synthetic import synthetic_dataset


@pytest.fixture
def folder(tmp_path):
    return synthetic_dataset(tmp_path / "data", n_train=2, n_test=1, duration=1.0, rate_hz=100.0)


def _edit_manifest(folder, **changes):
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest.update(changes)
    (folder / "manifest.json").write_text(json.dumps(manifest))


def _edit_signals(folder, name, **signals):
    path = folder / f"{name}.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(signals)
    np.savez(path, **arrays)


def test_round_trip(folder):
    data = load_dataset(folder)
    assert data.set == "sim" and data.sample_rate_hz == 100.0
    assert [t.name for t in data.split("train")] == ["train_000", "train_001"]
    assert [t.name for t in data.split("test")] == ["test_002"]
    traj = data.trajectories[0]
    assert set(traj.signals) == set(SIGNALS) and len(traj) == 100
    assert traj.reference["kind"] in ("circle", "spline") and traj.seed == 0
    assert data.plant["variant"] == "nominal"


@pytest.mark.parametrize("changes,message", [
    ({"format": "something-else"}, "format is 'something-else'.*flexff data collect"),
    ({"version": 2}, "version 2.*reads version 1.*collect the data again"),
    ({"set": "lab"}, "'set' is 'lab'"),
    ({"sample_rate_hz": -5}, "sample_rate_hz"),
    ({"trajectories": []}, "no trajectories"),
])
def test_bad_manifest_is_refused_with_advice(folder, changes, message):
    _edit_manifest(folder, **changes)
    with pytest.raises(DatasetError, match=message):
        load_dataset(folder)


def test_nan_is_reported_with_file_and_signal(folder):
    fx = np.load(folder / "train_001.npz")["Fx"].copy()
    fx[37] = np.nan
    _edit_signals(folder, "train_001", Fx=fx)
    with pytest.raises(DatasetError, match=r"train_001\.npz: signal 'Fx' has 1 NaN/Inf.*sample 37"):
        load_dataset(folder)


def test_unequal_lengths_are_refused(folder):
    _edit_signals(folder, "test_002", theta_s2=np.zeros(99))
    with pytest.raises(DatasetError, match="equal length"):
        load_dataset(folder)


def test_wrong_time_step_is_refused(folder):
    _edit_signals(folder, "train_000", time=np.arange(100) / 1000.0)
    with pytest.raises(DatasetError, match="sampled at the manifest's 100 Hz"):
        load_dataset(folder)


def test_missing_file_and_missing_folder(folder, tmp_path):
    (folder / "train_000.npz").unlink()
    with pytest.raises(DatasetError, match="train_000.npz is listed.*missing"):
        load_dataset(folder)
    with pytest.raises(DatasetError, match="manifest.json is missing"):
        load_dataset(tmp_path / "nowhere")


def test_missing_signal_is_named(folder):
    path = folder / "train_000.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "theta_s3"}
    np.savez(path, **arrays)
    with pytest.raises(DatasetError, match="lacks signals \\['theta_s3'\\]"):
        load_dataset(folder)
