"""Recorded signals of a run and their files.

Format: `signals.npz` (numpy's uncompressed zip of .npy arrays) holds `time` [s] and one float64
array per recorded signal, by its name (plant.signals for the manipulator's); it is the exact
record (a reload is bit-equal).
`signals.csv` is a copy for people and spreadsheets: a header `time,<signal>,...` and one row
per communication point, numbers written with 17 significant digits (also exact). Both files
are written to a temporary name in the same folder and then renamed, so an interrupted run
never leaves a half-written file behind.
"""

from __future__ import annotations

import csv as csv_module
import os
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexff.fmu.errors import InputError

NPZ_NAME = "signals.npz"
CSV_NAME = "signals.csv"


@dataclass(frozen=True, eq=False)
class Recording:
    """Signals sampled at the communication points `time` (one value per point each)."""

    time: np.ndarray
    signals: Mapping[str, np.ndarray]
    wall_s: float = 0.0  # seconds the stepping loop took (0 for a reloaded recording)
    timing: Any = None  # cosim.timing.StepTiming of the run (None for a reloaded recording)

    def __post_init__(self) -> None:
        if "time" in self.signals:
            raise InputError("'time' is reserved for the time axis and cannot be a signal name")
        for name, values in self.signals.items():
            if values.shape != self.time.shape:
                raise ValueError(f"signal {name!r} has {values.shape} samples, time has "
                                 f"{self.time.shape}")

    def __getitem__(self, name: str) -> np.ndarray:
        """A signal by its name, or by an output's own name where one FMU alone has it
        (`x` for `plant.x`)."""
        if name == "time":
            return self.time
        if name in self.signals:
            return self.signals[name]
        matches = [n for n in self.signals if n.partition(".")[2] == name]
        if len(matches) != 1:
            raise KeyError(name if not matches else f"{name!r} is ambiguous: {matches}")
        return self.signals[matches[0]]

    def __contains__(self, name: str) -> bool:
        try:
            self[name]
        except KeyError:
            return False
        return True

    @property
    def step(self) -> float:
        """Communication step [s] (the spacing of `time`)."""
        return float(self.time[1] - self.time[0]) if self.time.size > 1 else 0.0


def atomic_write(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call `write(tmp)` on a temporary file next to `path`, then rename it to `path` (what
    `write` returns is ignored)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o644)  # mkstemp creates the file private to its owner
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def save_recording(recording: Recording, folder: str | Path, csv: bool = True) -> list[Path]:
    """Write signals.npz (and signals.csv unless `csv` is false) into `folder`; return paths."""
    folder = Path(folder)
    arrays = {"time": recording.time, **recording.signals}

    def write_npz(tmp: Path) -> None:
        with open(tmp, "wb") as handle:  # a file object keeps numpy from appending ".npz"
            # numpy's stub types savez's **kwds and its allow_pickle: bool alike
            np.savez(handle, **arrays)  # type: ignore[arg-type]

    def write_csv(tmp: Path) -> None:
        if all(a.dtype == np.float64 for a in arrays.values()):
            np.savetxt(tmp, np.column_stack(list(arrays.values())), fmt="%.17g", delimiter=",",
                       header=",".join(arrays), comments="")
            return
        columns = [[f"{v:.17g}" if a.dtype.kind == "f" else str(v) for v in a]
                   for a in arrays.values()]
        with open(tmp, "w", newline="") as handle:
            writer = csv_module.writer(handle)
            writer.writerow(arrays)
            writer.writerows(zip(*columns))

    paths = [atomic_write(folder / NPZ_NAME, write_npz)]
    if csv:
        paths.append(atomic_write(folder / CSV_NAME, write_csv))
    return paths


def load_recording(path: str | Path) -> Recording:
    """Read a signals.npz written by save_recording (or the folder that holds it)."""
    path = Path(path)
    if path.is_dir():
        path = path / NPZ_NAME
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    if "time" not in arrays:
        raise InputError(f"{path}: no 'time' array, not a flexff recording")
    time = arrays.pop("time")
    return Recording(time, arrays)
