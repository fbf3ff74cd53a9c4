"""Logs of a real machine, for any machine: read (CSV, MATLAB v4-v7.3), checked, brought to
one sample rate, split by file, with the one rule for reference derivatives.

learning.logs (the manipulator's logs) and learning.machine_logs (a machine description's)
build on it; their module docs say what each checks and derives. Every error is a LogError
naming the file, the column and the row (`data row N`: 1-based, a CSV header not counted;
a CSV error names its line too).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.io import loadmat
from scipy.io.matlab import matfile_version
from scipy.signal import savgol_filter

from flexff.cosim.csv_text import TIME, read_time_table
from flexff.cosim.memory import check_memory
from flexff.cosim.references import SAVGOL_ORDER, SMOOTHING_WINDOW
from flexff.fmu.cache import file_sha256
from flexff.fmu.errors import InputError
from flexff.learning.manipulator_settings import manipulator_settings
from flexff.learning.presets import PRESETS
from flexff.learning.signal_processing import decimation

RATE_TOLERANCE = 0.01  # largest relative deviation of a sample interval from the median
UNIFORM = 1e-6  # relative: a grid this close to the rate is kept as it is (learning.dataset)
ROUNDING = 1e-3  # relative: the logs' rate is rounded to whole Hz within this


class LogError(InputError):
    """A log that cannot be imported; the message names the file, column and row."""


@dataclass(frozen=True)
class Log:
    """One log as read: its columns (the time column as `time`) and how to name row k."""

    path: Path
    format: str
    columns: dict[str, np.ndarray]
    row: Callable[[int], str]

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(np.median(np.diff(self.columns[TIME])))


def check_output(out: Path, rate_hz: float | None) -> None:
    """Refuse an output folder that holds files, and a rate that is no positive number."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise LogError(f"{out} exists and is not an empty folder: import into a new folder")
    if rate_hz is not None and not (np.isfinite(rate_hz) and rate_hz > 0):
        raise LogError(f"--rate must be a positive number of Hz, got {rate_hz}")


def log_entry(log: Log, how: str) -> dict[str, Any]:
    """A trajectory's manifest record of the log it came from and how it was resampled."""
    return {"path": str(log.path.resolve()), "format": log.format,
            "sha256": file_sha256(log.path), "rate_hz": log.rate_hz,
            "samples": len(log.columns[TIME]), "start_s": float(log.columns[TIME][0]),
            "resampled": how}


def split_by_file(paths: list[Path], test: Sequence[str] | None) -> dict[str, str]:
    """Each log's split by its name (the file name without suffix): those in `test` (default:
    the last) 'test', the others 'train'."""
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
def read_log(path: Path, required: Sequence[str], optional: Sequence[str],
             time: str = TIME) -> Log:
    """The log at `path` (.csv or .mat): its column `time` (kept as `time`), the `required`
    columns and those of `optional` it holds."""
    if not path.is_file():
        raise FileNotFoundError(2, "no such log file", str(path))
    if path.suffix.lower() == ".csv":
        table = read_time_table(path, required, optional, LogError, time)
        return Log(path, "csv", table.columns, table.row)
    if path.suffix.lower() == ".mat":
        return _read_mat(path, [time, *(n for n in required if n != time)], optional)
    raise LogError(f"{path}: not a .csv or .mat file")


def _read_mat(path: Path, required: list[str], optional: Sequence[str]) -> Log:
    """A MATLAB log; required[0] is its time variable."""
    try:
        major, _ = matfile_version(str(path))
    except Exception:
        raise LogError(f"{path}: not a MATLAB .mat file") from None
    wanted = [*required, *(n for n in optional if n not in required)]
    if major == 2:
        variables, kind = _read_hdf5(path, wanted), "MATLAB v7.3"
    else:
        try:
            variables = loadmat(str(path))
        except Exception as error:
            raise LogError(f"{path}: not a readable MATLAB file ({error})") from None
        kind = "MATLAB v4" if major == 0 else "MATLAB v5/v7"
    missing = [n for n in required if n not in variables]
    if missing:
        also = f" (optionally {', '.join(optional)})" if optional else ""
        raise LogError(f"{path}: missing column(s) {', '.join(missing)}: the variables must "
                       f"name {', '.join(required)}{also}")
    columns = {}
    for name in wanted:
        if name in variables:
            value = np.asarray(variables[name])
            if value.dtype.kind not in "fiu" or sum(d > 1 for d in value.shape) > 1:
                raise LogError(f"{path}: variable {name} is not a real vector (a {value.dtype} "
                               f"array of shape {value.shape})")
            columns[TIME if name == required[0] else name] = value.astype(np.float64).ravel()
    for name, values in columns.items():
        if values.size != columns[TIME].size:
            raise LogError(f"{path}: column {name} has {values.size} rows, time "
                           f"{columns[TIME].size}")
    return Log(path, kind, columns, lambda k: f"data row {k + 1}")


def _read_hdf5(path: Path, names: Sequence[str]) -> dict[str, np.ndarray]:
    """The top-level arrays `names` of a MATLAB v7.3 file (HDF5), with h5py."""
    try:
        import h5py
    except ImportError:
        raise LogError(f"{path}: this is a MATLAB v7.3 file: install h5py "
                       f"(pip install 'flexff[matlab]'), "
                       f"or save it as v7 (save -v7) or CSV") from None
    try:
        with h5py.File(path, "r") as handle:
            return {n: np.asarray(handle[n]) for n in names
                    if isinstance(handle.get(n), h5py.Dataset)}
    except OSError as error:
        raise LogError(f"{path}: not a readable MATLAB v7.3 file ({error})") from None


# -- checks and rate --------------------------------------------------------------------------
def check_log(log: Log) -> Log:
    """`log`, with every value finite and time strictly increasing at one rate."""
    for name, values in log.columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise LogError(f"{log.path}: column {name}, {log.row(int(bad[0]))}: NaN or Inf")
    time = log.columns[TIME]
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


def common_rate(logs: list[Log]) -> float:
    """The logs' rate: the first one's, rounded to a whole number of Hz where that changes it
    by at most ROUNDING (a logger's clock or jitter; the fast preset needs 100 Hz multiples)."""
    first = logs[0]
    for log in logs[1:]:
        if abs(log.rate_hz - first.rate_hz) > RATE_TOLERANCE * first.rate_hz:
            raise LogError(f"{log.path}: column time: sampled at {log.rate_hz:.6g} Hz, "
                           f"{first.path} at {first.rate_hz:.6g} Hz: give --rate HZ to "
                           f"resample them to one rate")
    rate_hz = first.rate_hz
    return float(round(rate_hz)) if abs(rate_hz - round(rate_hz)) <= ROUNDING * rate_hz else rate_hz


def resampled(log: Log, rate_hz: float) -> tuple[dict[str, np.ndarray], str]:
    """The log's columns at `rate_hz`, time from 0, and how they got there: kept bit for bit on
    a grid at `rate_hz`, every n-th sample at a whole multiple, else interpolated linearly."""
    columns = {**log.columns, TIME: log.columns[TIME] - log.columns[TIME][0]}
    time = columns[TIME]
    if _uniform(time, rate_hz):
        return columns, "kept"
    factor = log.rate_hz / rate_hz
    n = round(factor)
    if n >= 2 and abs(factor - n) <= UNIFORM * factor and _uniform(time[::n], rate_hz):
        return {k: v[::n] for k, v in columns.items()}, f"every {n}th sample kept"
    samples = int(np.floor(time[-1] * rate_hz + 1e-9)) + 1
    check_memory(samples * (len(columns) + 1),
                 f"{log.path}: its {time[-1]:.6g} s at {rate_hz:.6g} Hz (--rate)")
    grid = np.arange(samples) / rate_hz
    return ({k: np.interp(grid, time, v) for k, v in columns.items() if k != TIME}
            | {TIME: grid}), f"interpolated linearly from {log.rate_hz:.6g} Hz"


def _uniform(time: np.ndarray, rate_hz: float) -> bool:
    return bool(np.allclose(np.diff(time), 1.0 / rate_hz, rtol=UNIFORM, atol=1e-9))


def check_length(log: Log, samples: int, rate_hz: float) -> None:
    """At least one training window of every preset whose model rate divides `rate_hz`."""
    needed = []
    for preset, models in PRESETS.items():
        for kind in models:
            config, features = manipulator_settings(kind, preset)
            try:
                needed.append(config.window * decimation(rate_hz, features.model_rate_hz))
            except ValueError:  # that preset cannot train at this rate
                continue
    window = max(needed, default=0)
    if samples < window:
        raise LogError(f"{log.path}: column time: {samples} samples at {rate_hz:g} Hz, fewer than "
                       f"one training window ({window} samples, {window / rate_hz:g} s)")


# -- derived signals --------------------------------------------------------------------------
def reference_derivative(reference: np.ndarray, rate_hz: float, order: int, of: str
                         ) -> tuple[np.ndarray, str]:
    """The `order`-th derivative of the reference position `of` (its name in messages),
    sampled at `rate_hz`, by a cubic Savitzky-Golay filter over SMOOTHING_WINDOW (as
    cosim.references.read_csv derives them), and how, for a manifest's `derived`."""
    window = max(5, 2 * round(SMOOTHING_WINDOW * rate_hz / 2) + 1)
    values = savgol_filter(reference, window, SAVGOL_ORDER, deriv=order, delta=1.0 / rate_hz)
    return values, (f"{('first', 'second', 'third')[order - 1]} derivative of {of} (cubic "
                    f"Savitzky-Golay filter over {window} samples)")
