"""Several runs in parallel (cosim.executor: local processes by default, or a Dask cluster),
and sweeps that make them from one configuration.

Each run writes into <output_dir>/<config name>/. A run that fails (a bad configuration
included) is reported with its error in one line (and its traceback where FLEXFF_DEBUG=1,
which `flexff --debug` sets); the others carry on. With a Dask scheduler the workers must see
the same file system as this process (configuration files and output folder).
"""

from __future__ import annotations

import copy
import itertools
import os
import re
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flexff.cosim.config import expanded, parse_config, read_tables
from flexff.cosim.config_error import ConfigError
from flexff.cosim.executor import execute
from flexff.cosim.run import run_config
from flexff.cosim.schema import RunConfig
from flexff.fmu.errors import InputError


@dataclass(frozen=True)
class BatchResult:
    """The outcome of one run: its metrics, or the error that stopped it."""

    name: str
    output_dir: Path
    metrics: dict[str, Any] | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def _name(config: RunConfig | str | Path) -> str:
    return config.name if isinstance(config, RunConfig) else Path(config).stem


def _run_one(config: RunConfig | str | Path, output_dir: Path, debug: bool = False
             ) -> BatchResult:
    """Run one configuration, catching every error (it is returned, never raised); with
    `debug` the error carries its traceback."""
    name = _name(config)
    try:
        return BatchResult(name, output_dir, metrics=run_config(config, output_dir,
                                                                progress=False))
    except Exception as error:
        detail = "\n" + "".join(traceback.format_exception(error)) if debug else ""
        return BatchResult(name, output_dir, error=f"{type(error).__name__}: {error}{detail}")


def run_batch(configs: Sequence[RunConfig | str | Path], output_dir: str | Path,
              workers: int | None = None, scheduler: str | None = None,
              subfolders: bool = True) -> list[BatchResult]:
    """Run every configuration into output_dir/<name>/, in parallel; results in input order.

    `workers` caps the local processes (default: one per CPU); `scheduler` is the address of
    a Dask scheduler to run on instead (cosim.executor). A single configuration may write
    straight into output_dir (`subfolders=False`).

    >>> all(outcome.ok for outcome in api.run_many(configs, "sweep", workers=2))
    True
    """
    if not subfolders and len(configs) != 1:
        raise ValueError("several runs need one subfolder each")
    names = [_name(c) for c in configs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"configurations share the name(s) {twice}: each run needs its own "
                         f"output folder")
    debug = os.environ.get("FLEXFF_DEBUG") == "1"
    jobs = [(c, Path(output_dir) / n if subfolders else Path(output_dir), debug)
            for c, n in zip(configs, names)]
    results: dict[int, BatchResult] = {}
    with execute(_run_job, jobs, workers, scheduler) as running:
        for finished in running:  # _run_one returns its error; a dead worker gives one
            results[finished.index] = finished.result or BatchResult(
                names[finished.index], jobs[finished.index][1],
                error=f"{type(finished.error).__name__}: {finished.error}")
    return [results[k] for k in range(len(jobs))]


def _run_job(job: tuple[RunConfig | str | Path, Path, bool]) -> BatchResult:
    return _run_one(*job)


def sweep_axes(texts: Sequence[str]) -> dict[str, list[Any]]:
    """The sweep's axes from `TABLE.KEY=V1,V2,...` texts (`flexff run --sweep`), the values
    read as TOML; a key given twice is an error.

    >>> sweep_axes(["plant.m_up1=0.1,0.2", 'plant.variant="nominal"'])
    {'plant.m_up1': [0.1, 0.2], 'plant.variant': ['nominal']}"""
    import tomllib

    axes: dict[str, list[Any]] = {}
    for text in texts:
        key, sep, values = text.partition("=")
        if not sep or not values:
            raise InputError(f"--sweep expects TABLE.KEY=V1,V2,..., got {text!r}")
        try:
            parsed = tomllib.loads(f"v = [{values}]")["v"]
        except tomllib.TOMLDecodeError:
            raise InputError(f"--sweep values must be TOML values (strings quoted): "
                             f"{values!r}") from None
        if key.strip() in axes:
            raise InputError(f"--sweep {key.strip()} is given twice: list its values once")
        axes[key.strip()] = parsed
    return axes


def sweep(path: str | Path, axes: Mapping[str, Sequence[Any]]) -> list[RunConfig]:
    """Copies of the run configuration at `path` (TOML or SSP) with each key of `axes`
    (dotted: `plant.m_up1`, `fmu.vdp.parameters.mu`, `run.step`; a table in a list by its
    name: `fmu.pid.axes.x.crossover_hz`) set to each of its values, one
    copy per combination (the product, the last key varying fastest), named
    <stem>-<key>=<value>-...; each copy is checked like any configuration, its errors naming
    the file and key. A TOML file is edited as written (its short form included), an SSP file
    in the general form it reads as. Names are safe folder names (see _folder_name), made
    unique by a suffix; a value given twice is an error.

    >>> configs = api.sweep("run.toml", {"fmu.vdp.parameters.mu": [0.5, 1.5]})
    >>> configs[1].name
    'run-fmu.vdp.parameters.mu=1.5'"""
    path = Path(path)
    for key, values in axes.items():
        *tables, name = key.split(".")
        if not tables or not all(tables) or not name:
            raise InputError(f"a sweep key is table.key (e.g. plant.m_up1), got {key!r}")
        twice = next((v for k, v in enumerate(values) if v in values[:k]), None)
        if twice is not None:
            raise InputError(f"--sweep {key}: the sweep lists the same value twice: {twice!r}")
    base = _sweep_base(path)
    configs: list[RunConfig] = []
    names: list[str] = []
    for combination in itertools.product(*axes.values()):
        data = copy.deepcopy(base)
        for key, value in zip(axes, combination):
            _set(data, key, value, path)
        label = "-".join(f"{k}={v}" for k, v in zip(axes, combination))
        names.append(_unique(_folder_name(f"{path.stem}-{label}"), names))
        configs.append(parse_config(data, name=names[-1], base=path.resolve().parent,
                                    origin=str(path)))
    return configs


def _sweep_base(path: Path) -> dict[str, Any]:
    """The tables a sweep edits: a TOML file's own, an SSP file's in the general form."""
    if path.suffix.lower() == ".ssp":
        from flexff.cosim.ssp import load_ssp

        return expanded(load_ssp(path))
    return read_tables(path)


def _set(data: dict[str, Any], key: str, value: Any, path: Path) -> None:
    """Set the dotted `key` in the tables `data`; an FMU it names must be in the file."""
    *tables, name = key.split(".")
    fmus = data.get("fmu", {})
    if tables[0] == "fmu" and len(tables) > 1 and tables[1] not in fmus:
        raise ConfigError(str(path), key, f"no FMU {tables[1]!r} in the file (its FMUs: "
                                          f"{', '.join(fmus) or 'none'})")
    table: Any = data
    for k, part in enumerate(tables):
        table = _named(table, part, ".".join(tables[:k]), key, path) \
            if isinstance(table, list) else table.setdefault(part, {})
        if not isinstance(table, dict | list):
            raise ConfigError(str(path), key, f"{part!r} is not a table")
    if not isinstance(table, dict):
        raise ConfigError(str(path), key, f"{tables[-1]!r} lists tables: name one of them "
                                          f"({'.'.join(tables)}.NAME.{name})")
    table[name] = value


def _named(tables: list[Any], name: str, where: str, key: str, path: Path) -> dict[str, Any]:
    """The table of the list `tables` whose `name` is `name` (an axis of `axes = [{name =
    "x", ...}]` or of [[machine.axis]]): a sweep key addresses it as LIST.NAME.KEY."""
    found = [t for t in tables if isinstance(t, dict) and t.get("name") == name]
    if len(found) != 1:
        names = [str(t.get("name")) for t in tables if isinstance(t, dict) and "name" in t]
        raise ConfigError(str(path), key, f"{where} lists no table named {name!r} (its "
                                          f"tables' names: {', '.join(names) or 'none'})")
    return found[0]


def _folder_name(text: str) -> str:
    """`text` as one safe folder name: path separators and anything outside
    [A-Za-z0-9._=+-] become "_", and no ".." is left."""
    return re.sub(r"\.{2,}", "_", re.sub(r"[^A-Za-z0-9._=+-]", "_", text))


def _unique(name: str, taken: Sequence[str]) -> str:
    """`name`, or with the first suffix -2, -3, ... that is not taken yet."""
    k, unique = 1, name
    while unique in taken:
        k += 1
        unique = f"{name}-{k}"
    return unique
