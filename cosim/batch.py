"""Several runs in parallel: local processes by default, or a Dask cluster.

Each run writes into <output_dir>/<config name>/. A run that fails (a bad configuration
included) is reported with its error; the others carry on. With a Dask scheduler the workers
must see the same file system as this process (configuration files and output folder).
"""

from __future__ import annotations

import copy
import tomllib
import traceback
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.config import parse_config
from cosim.run import run_config
from cosim.schema import ConfigError, RunConfig


@dataclass(frozen=True)
class BatchResult:
    """The outcome of one run: its metrics, or the error that stopped it."""

    name: str
    output_dir: Path
    metrics: dict | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def _name(config: RunConfig | str | Path) -> str:
    return config.name if isinstance(config, RunConfig) else Path(config).stem


def _run_one(config: RunConfig | str | Path, output_dir: Path) -> BatchResult:
    """Run one configuration, catching every error (it is returned, never raised)."""
    name = _name(config)
    try:
        return BatchResult(name, output_dir, metrics=run_config(config, output_dir,
                                                                progress=False))
    except Exception as error:  # noqa: BLE001  (reported to the caller, the batch goes on)
        detail = "" if isinstance(error, (ConfigError, NotImplementedError)) else \
            "\n" + "".join(traceback.format_exception(error)[-3:])
        return BatchResult(name, output_dir, error=f"{type(error).__name__}: {error}{detail}")


def run_batch(configs: Sequence[RunConfig | str | Path], output_dir: str | Path,
              workers: int | None = None, scheduler: str | None = None,
              subfolders: bool = True) -> list[BatchResult]:
    """Run every configuration into output_dir/<name>/, in parallel; results in input order.

    `workers` caps the local processes (default: one per CPU); `scheduler` is the address of
    a Dask scheduler (dask.distributed, imported only then) to run on instead. A single
    configuration may write straight into output_dir (`subfolders=False`).
    """
    if not subfolders and len(configs) != 1:
        raise ValueError("several runs need one subfolder each")
    names = [_name(c) for c in configs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"configurations share the name(s) {twice}: each run needs its own "
                         f"output folder")
    folders = [Path(output_dir) / n if subfolders else Path(output_dir) for n in names]
    if scheduler is not None:
        return _run_dask(list(configs), folders, scheduler)
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_run_one, configs, folders))


def _run_dask(configs: list, folders: list[Path], scheduler: str) -> list[BatchResult]:
    try:
        from dask.distributed import Client
    except ImportError:
        raise RuntimeError("running on a Dask cluster needs dask.distributed: "
                           "pip install 'dask[distributed]'") from None
    with Client(scheduler) as client:
        futures = client.map(_run_one, configs, folders, pure=False)
        return client.gather(futures)


def sweep(path: str | Path, key: str, values: Sequence[Any]) -> list[RunConfig]:
    """Copies of the configuration file at `path` with the key `key` (dotted: `plant.m_up1`,
    `fmu.vdp.parameters.mu`) set to each value, named <stem>-<key>=<value>; each copy is
    checked like any configuration."""
    path = Path(path)
    *tables, name = key.split(".")
    if not tables or not all(tables) or not name:
        raise ValueError(f"a sweep key is table.key (e.g. plant.m_up1), got {key!r}")
    base = tomllib.loads(path.read_text())
    configs = []
    for value in values:
        data = copy.deepcopy(base)
        table = data
        for part in tables:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ValueError(f"--sweep {key}: {part!r} is not a table in {path}")
        table[name] = value
        configs.append(parse_config(data, name=f"{path.stem}-{key}={value}",
                                    base=path.resolve().parent, source=str(path)))
    return configs
