"""The disk a run's record is about to take, checked before it writes: a run of 10^18 steps is
a clear error naming the keys to change, not a full disk after minutes of writing."""

from __future__ import annotations

import shutil
from pathlib import Path

from flexff.cosim.config_error import ConfigError
from flexff.cosim.schema import RunConfig

# per value of signals.parquet (plain float64, uncompressed), twice: the chunks and the file
# they are joined into lie side by side until the join ends
PARQUET_BYTES = 2 * 8
CSV_BYTES = 25  # per value of signals.csv (17 significant digits, sign, exponent, comma)


def record_bytes(config: RunConfig, signals: int) -> int:
    """The bytes of the record of `config` with `signals` columns besides time: every
    `[record] every`-th point, in Parquet (and CSV where asked for)."""
    points = config.steps // config.record.every + 1
    per_value = PARQUET_BYTES + CSV_BYTES * config.record.csv
    return points * (1 + signals) * per_value


def check_disk(folder: Path, config: RunConfig, signals: int) -> None:
    """Refuse a run whose record of `signals` columns does not fit into the free space of
    `folder`'s file system (ConfigError naming run.stop and run.step)."""
    need, free = record_bytes(config, signals), shutil.disk_usage(folder).free
    if need > free:
        points = config.steps // config.record.every + 1
        raise ConfigError(config.origin, "run.stop, run.step",
                          f"the record of {points:.3g} points x {1 + signals} columns needs "
                          f"{need / 1e9:,.3g} GB, more than the {free / 1e9:,.3g} GB free in "
                          f"{folder}: shorten run.stop, enlarge run.step, record fewer signals "
                          f"([record] signals) or fewer points ([record] every), or free disk "
                          f"space")
