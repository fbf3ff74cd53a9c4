"""The dataset format: what is written is read back; every kind of bad folder is refused, a
damaged, swapped or edited one (sha256 of every file and of the manifest) included."""

import json
import shutil

import numpy as np
import pytest

from flexff.learning.dataset import (
    COLLECTED,
    CURRENT_SIGNALS,
    SIGNALS,
    DatasetError,
    load_dataset,
    write_manifest,
)
from flexff.learning.dataset_files import digest
from flexff.learning.synthetic import synthetic_dataset


@pytest.fixture
def folder(tmp_path):
    return synthetic_dataset(tmp_path / "data", n_train=2, n_test=1, duration=1.0, rate_hz=100.0)


def test_a_version_2_folder_without_currents_is_read(folder):
    for path in folder.glob("*.npz"):
        with np.load(path) as npz:
            arrays = {k: npz[k] for k in npz.files if k not in CURRENT_SIGNALS}
        np.savez(path, **arrays)
    _rewrite_manifest(folder)
    manifest = {**json.loads((folder / "manifest.json").read_text()), "version": 2}
    manifest["sha256"] = digest(manifest, splits=False)  # as version 2 wrote it
    (folder / "manifest.json").write_text(json.dumps(manifest))
    assert set(load_dataset(folder).trajectories[0].signals) == set(SIGNALS)


def test_some_currents_without_the_others_are_refused(folder):
    path = folder / "train_000.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "i3"}
    np.savez(path, **arrays)
    _rewrite_manifest(folder)
    with pytest.raises(DatasetError, match="holds i1, i2 but not all of i1, i2, i3"):
        load_dataset(folder)


def _edit_manifest(folder, **changes):
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest.update(changes)
    (folder / "manifest.json").write_text(json.dumps(manifest))


def _rewrite_manifest(folder, source=None):
    """The manifest written anew for the files as they are (as a writer of bad data would)."""
    manifest = json.loads((folder / "manifest.json").read_text())
    entries = [{k: v for k, v in e.items() if k != "sha256"} for e in manifest["trajectories"]]
    write_manifest(folder, manifest["set"], manifest["sample_rate_hz"], manifest["plant"],
                   entries, source or manifest["source"])


def _edit_signals(folder, name, **signals):
    path = folder / f"{name}.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(signals)
    np.savez(path, **arrays)
    _rewrite_manifest(folder)


def test_round_trip(folder):
    data = load_dataset(folder)
    assert data.set == "sim" and data.sample_rate_hz == 100.0
    assert [t.name for t in data.split("train")] == ["train_000", "train_001"]
    assert [t.name for t in data.split("test")] == ["test_002"]
    traj = data.trajectories[0]
    assert set(traj.signals) == {*SIGNALS, *CURRENT_SIGNALS} and len(traj) == 100
    assert traj.reference["kind"] in ("circle", "spline") and traj.seed == 0
    assert data.plant["variant"] == "nominal"


@pytest.mark.parametrize("changes,message", [
    ({"format": "something-else"}, "format is 'something-else'.*flexff data collect"),
    ({"version": 1}, "version 1.*reads versions 2, 3.*collect the data again"),
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
    with pytest.raises(DatasetError, match=r"train_000.npz is listed.*missing"):
        load_dataset(folder)
    with pytest.raises(DatasetError, match=r"manifest.json is missing"):
        load_dataset(tmp_path / "nowhere")


def test_missing_signal_is_named(folder):
    path = folder / "train_000.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "theta_s3"}
    np.savez(path, **arrays)
    _rewrite_manifest(folder)
    with pytest.raises(DatasetError, match="lacks signals \\['theta_s3'\\]"):
        load_dataset(folder)


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04 truncated"], ids=["empty", "truncated"])
def test_a_damaged_file_is_named(folder, content):
    (folder / "train_001.npz").write_bytes(content)
    with pytest.raises(DatasetError, match=r"train_001\.npz is truncated or not a \.npz file"):
        load_dataset(folder)


def test_a_damaged_file_of_a_collected_set_says_to_collect_again(folder):
    _rewrite_manifest(folder, source=COLLECTED)
    half = (folder / "test_002.npz").read_bytes()
    (folder / "test_002.npz").write_bytes(half[:len(half) // 2])
    with pytest.raises(DatasetError, match=r"test_002\.npz is truncated.*run flexff data collect "
                                           rf"--set sim -o {folder} again"):
        load_dataset(folder)


def test_swapped_files_are_refused(folder, tmp_path):
    shutil.move(folder / "train_000.npz", tmp_path / "swap.npz")
    shutil.move(folder / "train_001.npz", folder / "train_000.npz")
    shutil.move(tmp_path / "swap.npz", folder / "train_001.npz")
    with pytest.raises(DatasetError, match=r"train_000\.npz is not the file manifest.json lists "
                                           r"for trajectory 'train_000' \(its sha256 differs"):
        load_dataset(folder)


@pytest.mark.parametrize("key, value", [("set", "hardware"), ("plant", {"variant": "hardware"}),
                                        ("sample_rate_hz", 200.0)])
def test_an_edited_manifest_is_refused(folder, key, value):
    _edit_manifest(folder, **{key: value})
    with pytest.raises(DatasetError, match=r"manifest.json was edited.*only a trajectory's "
                                           "'split' may be changed"):
        load_dataset(folder)


def test_splits_may_be_edited_and_change_the_digest(folder):
    before = load_dataset(folder).digest
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["trajectories"][0]["split"] = "test"
    (folder / "manifest.json").write_text(json.dumps(manifest))
    after = load_dataset(folder)
    assert [t.name for t in after.split("test")] == ["train_000", "test_002"]
    assert after.digest != before
