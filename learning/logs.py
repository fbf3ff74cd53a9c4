"""`flexff data import`: logs of a real machine (CSV or MATLAB .mat) as a dataset folder.

Each file is one trajectory, named by its file name without suffix. Columns (CSV: a header row
naming them; .mat: variables of those names, vectors): `time` [s], `theta_s1..3` [rad, the
shoulder angles as flexff's plant gives them: the wrist at the centre at the home angles],
`Fx`, `Fy` [N] (the force applied to the wrist) are required; the reference `x_ref .. ay_ref`
is optional; other columns are ignored. MATLAB v4/v5/v7 files are read by scipy, v7.3 files
(HDF5) by h5py where it is installed.

Everything is checked before anything is written, and an error names the file, the column and
the row (`data row N`: 1-based, the CSV header not counted; a CSV error names its line too): a
missing column, NaN or Inf, time not strictly increasing, a sample interval more than 1 % off
the file's median, fewer samples than one training window (learning.presets), encoder angles
that no wrist position fits.

Time is counted from each log's first sample (its own first time is kept in the manifest).
The dataset's rate is `rate` or the logs' own (which must agree to 1 %; rounded to a whole
number of Hz where that changes it by at most 0.1 %). A log already sampled
at that rate (to the dataset loader's 1e-6) is kept bit for bit; one at a whole multiple keeps
every n-th sample (plain decimation, as data collection); any other is interpolated linearly
onto a uniform grid from its first time.

What the format needs and the logs do not hold is derived, and marked so in the trajectory's
manifest entry (`derived`): the true position x, y from the encoders by the nominal forward
kinematics (three encoders, least squares), and a missing reference signal: a position from
the derived position, a velocity or acceleration by a cubic Savitzky-Golay filter over
SMOOTHING_S of the reference position, as cosim.references.read_csv derives them. Training
reads only the encoders and the forces (learning.dataset.TRAINED), never a derived signal.

The folder is written under a temporary name beside `out` and renamed at the end, so an error
leaves `out` as it was.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.io import loadmat
from scipy.io.matlab import matfile_version
from scipy.signal import savgol_filter

from flexff.cosim.csv_text import read_time_table
from flexff.fmu.cache import file_sha256
from flexff.fmu.errors import InputError
from flexff.learning.dataset import (
    ENCODER_SIGNALS,
    IMPORTED,
    POSITION_SIGNALS,
    REFERENCE_SIGNALS,
    TRAINED,
    Dataset,
    load_dataset,
    save_signals,
    write_manifest,
)
from flexff.learning.features import decimation, encoder_positions
from flexff.learning.presets import PRESETS, make_config

REQUIRED = TRAINED  # a log must hold what training reads
COLUMNS = (*REQUIRED, *REFERENCE_SIGNALS)
RATE_TOLERANCE = 0.01  # largest relative deviation of a sample interval from the median
UNIFORM = 1e-6  # relative: a grid this close to the rate is kept as it is (learning.dataset)
ROUNDING = 1e-3  # relative: the logs' rate is rounded to whole Hz within this
SMOOTHING_S = 0.025  # Savitzky-Golay window of derived reference derivatives (read_csv's)
SET = "hardware"  # logs of a real machine
FK = "forward kinematics of theta_s1..3 (nominal model, least squares)"


class LogError(InputError):
    """A log that cannot be imported; the message names the file, column and row."""


@dataclass(frozen=True)
class _Log:
    """One log as read: its known columns and how to name row k in messages."""

    path: Path
    format: str
    columns: dict[str, np.ndarray]
    row: Callable[[int], str]

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(np.median(np.diff(self.columns["time"])))


def import_logs(files: Sequence[str | Path], out: str | Path, rate_hz: float | None = None,
                test: Sequence[str] | None = None) -> Dataset:
    """Import the log `files` into the new dataset folder `out` at `rate_hz` (default: the
    logs' own), the logs named in `test` (default: the last one) forming the test split;
    return the dataset. Raises LogError (an InputError) naming file, column and row."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise LogError(f"{out} exists and is not an empty folder: import into a new folder")
    if rate_hz is not None and not (np.isfinite(rate_hz) and rate_hz > 0):
        raise LogError(f"--rate must be a positive number of Hz, got {rate_hz}")
    paths = [Path(f) for f in files]
    splits = _splits(paths, test)
    logs = [_checked(_read(p)) for p in paths]
    rate = rate_hz or _common_rate(logs)
    trajectories = [(log, *_resampled(log, rate)) for log in logs]
    for log, signals, _ in trajectories:
        _check_length(log, len(signals["time"]), rate)
    entries, written = [], []
    for log, signals, how in trajectories:
        derived = _derive(log, signals, rate)
        written.append(signals)
        entries.append({"name": log.path.stem, "split": splits[log.path.stem],
                        "file": f"{log.path.stem}.npz", "reference": {}, "seed": 0,
                        "derived": derived,
                        "log": {"path": str(log.path.resolve()), "format": log.format,
                                "sha256": file_sha256(log.path), "rate_hz": log.rate_hz,
                                "samples": len(log.columns["time"]),
                                "start_s": float(log.columns["time"][0]), "resampled": how}})
    _write(out, rate, entries, written)
    return load_dataset(out)


def _splits(paths: list[Path], test: Sequence[str] | None) -> dict[str, str]:
    names = [p.stem for p in paths]
    for k, name in enumerate(names):
        if name in names[:k]:
            raise LogError(f"{paths[names.index(name)]} and {paths[k]} have the same name "
                           f"{name!r}: rename one (a trajectory is named after its file)")
    if len(paths) < 2:
        raise LogError("one log: training needs at least one log for training and one for the "
                       "test split (--test)")
    test = [names[-1]] if test is None else list(test)
    if not test:
        raise LogError("--test names no log: name the logs of the test split")
    unknown = [n for n in test if n not in names]
    if unknown:
        raise LogError(f"--test: no log named {', '.join(unknown)} (the logs: "
                       f"{', '.join(names)})")
    if set(test) >= set(names):
        raise LogError("--test names every log: leave at least one for training")
    return {n: "test" if n in test else "train" for n in names}


# -- reading ----------------------------------------------------------------------------------
def _read(path: Path) -> _Log:
    if not path.is_file():
        raise FileNotFoundError(2, "no such log file", str(path))
    if path.suffix.lower() == ".csv":
        return _read_csv(path)
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    raise LogError(f"{path}: not a .csv or .mat file")


def _read_csv(path: Path) -> _Log:
    """A CSV log: cosim.csv_text's time table of the known columns."""
    table = read_time_table(path, REQUIRED, REFERENCE_SIGNALS, LogError)
    return _Log(path, "csv", table.columns, table.row)


def _read_mat(path: Path) -> _Log:
    try:
        major, _ = matfile_version(str(path))
    except Exception:
        raise LogError(f"{path}: not a MATLAB .mat file") from None
    if major == 2:
        variables, kind = _read_hdf5(path), "MATLAB v7.3"
    else:
        try:
            variables = loadmat(str(path))
        except Exception as error:
            raise LogError(f"{path}: not a readable MATLAB file ({error})") from None
        kind = "MATLAB v4" if major == 0 else "MATLAB v5/v7"
    _require(path, [n for n in REQUIRED if n not in variables], "the variables")
    columns = {}
    for name in COLUMNS:
        if name in variables:
            value = np.asarray(variables[name])
            if value.dtype.kind not in "fiu" or sum(d > 1 for d in value.shape) > 1:
                raise LogError(f"{path}: variable {name} is not a real vector (a {value.dtype} "
                               f"array of shape {value.shape})")
            columns[name] = value.astype(np.float64).ravel()
    for name, values in columns.items():
        if values.size != columns["time"].size:
            raise LogError(f"{path}: column {name} has {values.size} rows, time "
                           f"{columns['time'].size}")
    return _Log(path, kind, columns, lambda k: f"data row {k + 1}")


def _read_hdf5(path: Path) -> dict[str, np.ndarray]:
    """The top-level arrays of a MATLAB v7.3 file (HDF5), with h5py."""
    try:
        import h5py
    except ImportError:
        raise LogError(f"{path}: this is a MATLAB v7.3 file: install h5py "
                       f"(pip install 'flexff[matlab]'), "
                       f"or save it as v7 (save -v7) or CSV") from None
    try:
        with h5py.File(path, "r") as handle:
            return {n: np.asarray(handle[n]) for n in COLUMNS
                    if isinstance(handle.get(n), h5py.Dataset)}
    except OSError as error:
        raise LogError(f"{path}: not a readable MATLAB v7.3 file ({error})") from None


def _require(path: Path, missing: list[str], where: str) -> None:
    if missing:
        raise LogError(f"{path}: missing column(s) {', '.join(missing)}: {where} must name "
                       f"{', '.join(REQUIRED)} (optionally {', '.join(REFERENCE_SIGNALS)})")


# -- checks and rate --------------------------------------------------------------------------
def _checked(log: _Log) -> _Log:
    """`log`, with every value finite and time strictly increasing at one rate."""
    for name, values in log.columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise LogError(f"{log.path}: column {name}, {log.row(int(bad[0]))}: NaN or Inf")
    time = log.columns["time"]
    if time.size < 2:
        raise LogError(f"{log.path}: {time.size} data row(s), too few for a training window")
    steps = np.diff(time)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise LogError(f"{log.path}: column time, {log.row(k)}: time does not increase "
                       f"(t = {time[k - 1]:.9g} s, then {time[k]:.9g} s)")
    median = float(np.median(steps))
    off = np.abs(steps - median) > RATE_TOLERANCE * median
    if np.any(off):
        k = int(np.argmax(off)) + 1
        raise LogError(f"{log.path}: column time, {log.row(k)}: a sample interval of "
                       f"{steps[k - 1]:.6g} s, more than 1 % off the log's {median:.6g} s (a gap "
                       f"or jitter: a log must hold one sample rate)")
    return log


def _common_rate(logs: list[_Log]) -> float:
    """The logs' rate: the first one's, rounded to a whole number of Hz where that changes it
    by at most ROUNDING (a logger's clock or jitter; the fast preset needs 100 Hz multiples)."""
    first = logs[0]
    for log in logs[1:]:
        if abs(log.rate_hz - first.rate_hz) > RATE_TOLERANCE * first.rate_hz:
            raise LogError(f"{log.path}: column time: sampled at {log.rate_hz:.6g} Hz, "
                           f"{first.path} at {first.rate_hz:.6g} Hz: give --rate HZ to "
                           f"resample them to one rate")
    rate = first.rate_hz
    return float(round(rate)) if abs(rate - round(rate)) <= ROUNDING * rate else rate


def _resampled(log: _Log, rate: float) -> tuple[dict[str, np.ndarray], str]:
    """The log's columns at `rate`, time from 0, and how they got there."""
    columns = {**log.columns, "time": log.columns["time"] - log.columns["time"][0]}
    time = columns["time"]
    if _uniform(time, rate):
        return columns, "kept"
    factor = log.rate_hz / rate
    n = round(factor)
    if n >= 2 and abs(factor - n) <= UNIFORM * factor and _uniform(time[::n], rate):
        return {k: v[::n] for k, v in columns.items()}, f"every {n}th sample kept"
    grid = np.arange(int(np.floor(time[-1] * rate + 1e-9)) + 1) / rate
    return ({k: np.interp(grid, time, v) for k, v in columns.items() if k != "time"}
            | {"time": grid}), f"interpolated linearly from {log.rate_hz:.6g} Hz"


def _uniform(time: np.ndarray, rate: float) -> bool:
    return bool(np.allclose(np.diff(time), 1.0 / rate, rtol=UNIFORM, atol=1e-9))


def _check_length(log: _Log, samples: int, rate: float) -> None:
    """At least one training window of every preset whose model rate divides `rate`."""
    needed = []
    for preset, models in PRESETS.items():
        for kind in models:
            config = make_config(kind, preset)
            try:
                needed.append(config.window * decimation(rate, config.features.model_rate_hz))
            except ValueError:  # that preset cannot train at this rate
                continue
    window = max(needed, default=0)
    if samples < window:
        raise LogError(f"{log.path}: column time: {samples} samples at {rate:g} Hz, fewer than "
                       f"one training window ({window} samples, {window / rate:g} s)")


# -- derived signals --------------------------------------------------------------------------
def _derive(log: _Log, signals: dict[str, np.ndarray], rate: float) -> dict[str, str]:
    """Add the signals the log lacks to `signals`; return how each was derived."""
    theta = np.column_stack([signals[n] for n in ENCODER_SIGNALS])
    position = encoder_positions(theta, 3)
    bad = np.flatnonzero(~np.all(np.isfinite(position), axis=1))
    if bad.size:
        raise LogError(f"{log.path}: columns theta_s1..3, data row {bad[0] + 1} (after "
                       f"resampling): no wrist position fits these angles (are they the shoulder "
                       f"angles in rad, as flexff's plant gives them?)")
    derived = {}
    for axis, column in zip(POSITION_SIGNALS, position.T):
        signals[axis] = np.ascontiguousarray(column)
        derived[axis] = FK
    window = max(5, 2 * round(SMOOTHING_S * rate / 2) + 1)
    for axis in POSITION_SIGNALS:
        ref = f"{axis}_ref"
        if ref not in signals:
            signals[ref] = signals[axis]
            derived[ref] = f"the derived position {axis} (the log has no {ref})"
        for order, prefix in ((1, "v"), (2, "a")):
            name = f"{prefix}{axis}_ref"
            if name not in signals:
                signals[name] = savgol_filter(signals[ref], window, 3, deriv=order,
                                              delta=1.0 / rate)
                derived[name] = (f"{('first', 'second')[order - 1]} derivative of "
                                 f"{'the derived ' if ref in derived else ''}{ref} (cubic "
                                 f"Savitzky-Golay filter over {window} samples)")
    return derived


# -- writing ----------------------------------------------------------------------------------
def _write(out: Path, rate: float, entries: list[dict[str, Any]],
           signals: list[dict[str, Any]]) -> None:
    """The dataset folder, written under a temporary name beside `out`, then renamed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        for entry, values in zip(entries, signals):
            save_signals(tmp / entry["file"], values)
        write_manifest(tmp, SET, rate, {"kind": "measured logs"}, entries, IMPORTED)
        os.chmod(tmp, 0o755)  # mkdtemp's folder is private to its owner
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
