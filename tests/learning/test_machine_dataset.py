"""Machine datasets (version 4): what is written is read back with its description; a folder
meeting another description, an edited or damaged one, and the other format's folders are
refused with one line saying what to do."""

import json
import shutil

import numpy as np
import pytest

from flexff.cosim.machine import parse_machine
from flexff.learning.dataset import load_dataset
from flexff.learning.dataset_files import DatasetError
from flexff.learning.machine_dataset import (
    describe,
    load_machine_dataset,
    write_machine_dataset,
    write_machine_manifest,
)
from flexff.learning.synthetic import synthetic_dataset

AXIS = {"name": "x", "measured": "plant.x", "feedforward": "pid.x_ff", "effort": "pid.x_effort",
        "range": [-0.05, 0.05], "velocity": 0.2, "acceleration": 2.0}
RATE = 100.0


def drive(machine_name="drive", **axis):
    return parse_machine({"name": machine_name, "axis": [{**AXIS, **axis}]}, "drive.toml")


def runs(machine, n=3):
    rng = np.random.default_rng(4)
    time = np.arange(50) / RATE
    return {f"run-{k}": {"time": time, **{s: rng.normal(size=50) for s in machine.signals}}
            for k in range(n)}


@pytest.fixture
def folder(tmp_path):
    machine = drive()
    dataset = write_machine_dataset(
        tmp_path / "data", machine, runs(machine), RATE,
        {"run-0": "train", "run-1": "train", "run-2": "test"}, "a test",
        {"run-2": {"derived": {"x_ref": "made for the test"}}})
    return dataset.path


def test_what_is_written_is_read_back(folder):
    machine = drive()
    dataset = load_machine_dataset(folder, machine)
    assert dataset.machine == describe(machine) and dataset.sample_rate_hz == RATE
    assert dataset.signals == ("time", *machine.signals)
    assert [t.name for t in dataset.split("test")] == ["run-2"]
    assert dataset.trajectories[2].derived == {"x_ref": "made for the test"}
    for traj, values in zip(dataset.trajectories, runs(machine).values()):
        assert all(np.array_equal(traj.signals[s], values[s]) for s in dataset.signals)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert (manifest["version"], manifest["source"]) == (4, "a test")
    assert manifest["machine"]["axes"][0] == {
        "name": "x", "unit": "m", "effort_unit": "N", "signals": {
            "reference": "x_ref", "derivatives": ["vx_ref", "ax_ref", "jx_ref"],
            "measured": "x_measured", "effort": "x_effort"}}


@pytest.mark.parametrize("other, where", [
    (drive(unit="mm"), "machine.axes[0].unit is 'm' in the folder, 'mm' in the description"),
    (drive(name="q"), "machine.axes[0].name is 'x' in the folder, 'q' in the description"),
    (drive("press"), "machine.name is 'drive' in the folder, 'press' in the description"),
    (parse_machine({"axis": [AXIS, {**AXIS, "name": "y"}]}, "two.toml"),
     "machine.axes: 1 in the folder, 2 in the description"),
])
def test_another_description_is_refused(folder, other, where):
    with pytest.raises(DatasetError) as error:
        load_machine_dataset(folder, other)
    assert str(error.value) == (f"{folder / 'manifest.json'}: written for another machine "
                                f"description ({where}): use the description it was written "
                                f"for, or write it again (a test) with this one")


def test_the_manipulator_format_and_this_refuse_each_other(folder, tmp_path):
    manipulator = synthetic_dataset(tmp_path / "v3", n_train=1, n_test=1, duration=1.0,
                                    rate_hz=100.0)
    with pytest.raises(DatasetError, match=r"a dataset of version 3, the manipulator's signals "
                                           r"without a machine description: read it with "
                                           r"learning\.dataset\.load_dataset"):
        load_machine_dataset(manipulator)
    with pytest.raises(DatasetError, match=r"a dataset of version 4 \(a machine description's "
                                           r"signals\), not the manipulator's: read it with "
                                           r"learning\.machine_dataset\.load_machine_dataset"):
        load_dataset(folder)


def test_an_edited_or_damaged_folder_is_refused(folder, tmp_path):
    manifest_path = folder / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["trajectories"][0]["split"] = "test"  # a split may be edited by hand
    manifest_path.write_text(json.dumps(manifest))
    assert load_machine_dataset(folder).trajectories[0].split == "test"
    manifest["machine"]["axes"][0]["unit"] = "mm"
    manifest_path.write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match=r"manifest\.json was edited: its machine"):
        load_machine_dataset(folder)
    manifest["machine"]["axes"][0]["unit"] = "m"
    manifest_path.write_text(json.dumps(manifest))
    damaged = tmp_path / "damaged"
    shutil.copytree(folder, damaged)
    shutil.copy(damaged / "run-0.npz", damaged / "run-1.npz")
    with pytest.raises(DatasetError, match=r"run-1\.npz is not the file manifest\.json lists "
                                           r"for trajectory 'run-1'"):
        load_machine_dataset(damaged)


def test_only_references_may_be_derived(folder):
    entries = [{k: v for k, v in e.items() if k != "sha256"} for e in
               json.loads((folder / "manifest.json").read_text())["trajectories"]]
    entries[1]["derived"] = {"x_effort": "made up"}
    with pytest.raises(DatasetError, match=r"trajectory 'run-1': x_effort marked derived, but "
                                           r"only references may be"):
        write_machine_manifest(folder, drive(), RATE, entries, "a test")


def test_a_trajectory_without_every_signal_is_not_written(tmp_path):
    machine = drive()
    values = runs(machine, 2)
    del values["run-1"]["jx_ref"]
    with pytest.raises(DatasetError, match="run-1: trajectory lacks signals jx_ref"):
        write_machine_dataset(tmp_path / "data", machine, values, RATE,
                              {"run-0": "train", "run-1": "test"}, "a test")
    assert not (tmp_path / "data").exists() and not list(tmp_path.iterdir())
