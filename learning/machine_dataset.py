"""Datasets of any machine on disk: a folder with `manifest.json` and one `.npz` per trajectory
(`time` and the machine's signals: references, measured positions, efforts).

The manifest (format FORMAT) holds the machine description (cosim.machine's table), the
sample rate, where the data came from and, per trajectory, its name, split, file and the
sha256 of the file; the manifest's own sha256 covers all but the splits (which may be edited
by hand). Reading checks all of it and each file's columns, so that a truncated, swapped or
foreign file is refused with a message naming it (DatasetError).
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.cosim.machine import Machine, machine_table, parse_machine
from flexff.cosim.recording import atomic_write
from flexff.fmu.cache import file_sha256
from flexff.learning.dataset import DatasetError

FORMAT = "flexff-machine-dataset"
VERSION = 1
MANIFEST = "manifest.json"
SPLITS = ("train", "test")


@dataclass(frozen=True)
class MachineTrajectory:
    """One trajectory of a machine's data: its name, split ("train" or "test") and signals
    (time and machine.signals), sampled at the data's rate."""

    name: str
    split: str
    signals: Mapping[str, np.ndarray]


@dataclass(frozen=True)
class MachineDataset:
    """A loaded dataset: its machine, rate, trajectories and the digest naming its content."""

    path: Path
    machine: Machine
    sample_rate_hz: float
    trajectories: list[MachineTrajectory]
    digest: str
    source: str


def write_trajectory(folder: Path, name: str, signals: Mapping[str, np.ndarray],
                     machine: Machine) -> dict[str, Any]:
    """One trajectory's .npz (time and machine.signals, float64), atomically; its entry."""
    missing = [n for n in ("time", *machine.signals) if n not in signals]
    if missing:
        raise DatasetError(f"trajectory {name!r} lacks {', '.join(missing)}")
    arrays = {n: np.asarray(signals[n], dtype=np.float64) for n in ("time", *machine.signals)}
    file = f"{name}.npz"

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)  # type: ignore[arg-type]

    atomic_write(folder / file, write)
    return {"name": name, "file": file}


def write_manifest(folder: Path, machine: Machine, rate_hz: float,
                   entries: Sequence[Mapping[str, Any]], source: str,
                   extra: Mapping[str, Any] | None = None) -> Path:
    """The manifest of the trajectory files in `folder` (entries: name, split, file, ...)."""
    manifest = {"format": FORMAT, "version": VERSION, "source": source,
                "sample_rate_hz": rate_hz, "machine": machine_table(machine), **(extra or {}),
                "trajectories": [{**e, "sha256": file_sha256(folder / e["file"])}
                                 for e in entries]}
    manifest["sha256"] = _digest(manifest)
    text = json.dumps(manifest, indent=2) + "\n"
    return atomic_write(folder / MANIFEST, lambda tmp: tmp.write_text(text, "utf-8"))


def _digest(manifest: Mapping[str, Any]) -> str:
    """sha256 of the manifest less its own digest and the trajectories' splits."""
    content = {k: v for k, v in manifest.items() if k != "sha256"}
    content["trajectories"] = [{k: v for k, v in e.items() if k != "split"}
                               for e in manifest["trajectories"]]
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def is_machine_dataset(path: str | Path) -> bool:
    """Whether the folder holds a machine's dataset (not the manipulator's)."""
    try:
        return bool(json.loads((Path(path) / MANIFEST).read_text()).get("format") == FORMAT)
    except (OSError, ValueError, AttributeError):
        return False


def load_machine_dataset(path: str | Path) -> MachineDataset:
    """Read and check a machine's dataset folder."""
    folder = Path(path)
    where = folder / MANIFEST
    try:
        manifest = json.loads(where.read_text("utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{folder} holds no {MANIFEST}: collect a dataset with flexff data "
                           f"collect --loop LOOP.toml, or import logs") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise DatasetError(f"{where} is not valid JSON ({error})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT \
            or manifest.get("version") != VERSION:
        raise DatasetError(f"{where}: not a machine dataset of format {FORMAT!r} version "
                           f"{VERSION}")
    if manifest.get("sha256") != _digest(manifest):
        raise DatasetError(f"{where} was changed after it was written (its sha256 differs): "
                           f"collect or import the data again")
    machine = parse_machine(manifest["machine"], str(where))
    rate = float(manifest["sample_rate_hz"])
    trajectories = []
    for entry in manifest["trajectories"]:
        if entry.get("split") not in SPLITS:
            raise DatasetError(f"{where}: trajectory {entry.get('name')!r} has split "
                               f"{entry.get('split')!r}, expected one of {', '.join(SPLITS)}")
        file = folder / entry["file"]
        if not file.is_file() or file_sha256(file) != entry["sha256"]:
            raise DatasetError(f"{file} is missing or not the file the manifest lists (sha256): "
                               f"collect or import the data again")
        try:
            with np.load(io.BytesIO(file.read_bytes())) as arrays:
                signals = {n: arrays[n] for n in ("time", *machine.signals)}
        except (KeyError, ValueError, zipfile.BadZipFile, OSError) as error:
            raise DatasetError(f"{file}: not the machine's signals ({error})") from None
        trajectories.append(MachineTrajectory(entry["name"], entry["split"], signals))
    return MachineDataset(folder, machine, rate, trajectories, manifest["sha256"],
                          str(manifest.get("source", "")))
