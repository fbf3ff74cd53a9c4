"""Fuzzing run configurations (cosim.config.load_config and parse_config, what `flexff run` and
every command taking a configuration read): the repository's example configurations with keys
removed, added and given odd values, their files' bytes mutated, and garbage
(tests/fuzz/harness.py)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from flexff.cosim.config import load_config, parse_config, read_tables
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import garbage, mutated_bytes, odd_values
from tests.helpers import REPOSITORY

FILES = sorted([*(REPOSITORY / "flexff" / "cosim" / "examples").glob("*.toml"),
                *(REPOSITORY / "flexff" / "machines" / "examples").glob("*.toml")])
EXAMPLES = [(read_tables(path), path.read_text(), path.parent) for path in FILES]


def _walk(value: Any) -> tuple[set[str], list[Any]]:
    """Every key and every scalar value in `value`, nested tables and lists included."""
    if isinstance(value, dict):
        keys, scalars = set(value), []
        for inner in value.values():
            more, found = _walk(inner)
            keys |= more
            scalars += found
        return keys, scalars
    if isinstance(value, list):
        keys, scalars = set(), []
        for inner in value:
            more, found = _walk(inner)
            keys |= more
            scalars += found
        return keys, scalars
    return set(), [value]


KEYS = sorted(set().union(*(_walk(tables)[0] for tables, _, _ in EXAMPLES)))
# the examples' own values (builtin names, kinds, file names) and the files beside them
SCALARS = sorted({repr(v): v for tables, _, _ in EXAMPLES for v in _walk(tables)[1]}.values(),
                 key=repr)
FILE_NAMES = sorted({p.name for folder in {f.parent for f in FILES} for p in folder.iterdir()})
values = st.one_of(odd_values(), st.sampled_from(SCALARS), st.sampled_from(FILE_NAMES))


@st.composite
def mutated_tables(draw: st.DrawFn, tables: dict[str, Any]) -> dict[str, Any]:
    """`tables` with one to four edits, each at a random depth: a key or item removed, a value
    replaced by an odd one or another table's, a known or odd key added, an item repeated."""
    data = copy.deepcopy(tables)
    for _ in range(draw(st.integers(1, 4))):
        node: Any = data
        while True:
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            at = draw(st.sampled_from(keys)) if keys else None
            if at is not None and isinstance(node[at], (dict, list)) and draw(st.booleans()):
                node = node[at]
                continue
            break
        edit = draw(st.sampled_from(["remove", "replace", "add", "repeat"]))
        if edit == "remove" and at is not None:
            del node[at]
        elif edit == "replace" and at is not None:
            node[at] = draw(values)
        elif edit == "repeat" and at is not None and isinstance(node, list):
            node.append(copy.deepcopy(node[at]))
        elif isinstance(node, dict):
            node[draw(st.one_of(st.sampled_from(KEYS), st.text(max_size=8)))] = draw(values)
        else:
            node.append(draw(values))
    return data


CIRCLE = {"reference": {"kind": "circle", "radius": 0.02, "duration": 8.0}}
chosen = st.sampled_from(EXAMPLES)
configs = st.one_of(
    chosen.flatmap(lambda e: st.tuples(mutated_tables(e[0]), st.just(e[2]))),
    chosen.flatmap(lambda e: st.tuples(mutated_bytes(e[1].encode()), st.just(e[2]))),
    st.tuples(garbage(), st.just(REPOSITORY)))
Config = tuple[dict[str, Any] | bytes, Path]


@pytest.fixture(scope="module")
def mirrors(tmp_path_factory: pytest.TempPathFactory) -> dict[Path, Path]:
    """For each examples folder, a folder of links to its files, where a mutated file is
    written: its relative paths find the example's files."""
    out = {}
    for folder in {*(e[2] for e in EXAMPLES), REPOSITORY}:
        mirror = tmp_path_factory.mktemp(folder.name)
        for path in folder.iterdir():
            (mirror / path.name).symlink_to(path)
        out[folder] = mirror
    return out


def fuzz_config(config: Config, mirrors: dict[Path, Path]) -> None:
    """The property for one configuration: tables checked against their folder, or a file's
    bytes read from it (load_config)."""
    data, base = config
    if isinstance(data, dict):
        check(lambda: parse_config(data, base=base, origin="fuzz.toml"))
        return
    path = mirrors[base] / "fuzz.toml"
    path.write_bytes(data)
    check(lambda: load_config(path))


@fast()
@given(config=configs)
# found by the fuzzer: a table named "\r" made a message of two lines (fmu.errors.one_line)
@example(config=({"run": {"step": 0.001}, "\r": "N"}, REPOSITORY))
# found by the fuzzer: a list as [feedforward] kind was a TypeError (unhashable)
@example(config=({**CIRCLE, "feedforward": {"kind": [1]}}, REPOSITORY))
# found by the fuzzer: a line of 2^31 s was checked on a grid of 31 TiB (a MemoryError)
@example(config=({"reference": {"kind": "line-circle", "radius": 0.02, "line_duration": 2**31,
                                "circle_duration": 8.0}}, REPOSITORY))
# found by the fuzzer: a step of 5e-324 s made infinitely many samples (an OverflowError)
@example(config=({**CIRCLE, "run": {"step": 5e-324}}, REPOSITORY))
# found by the fuzzer: a path with a name over 255 bytes was an OSError (ENAMETOOLONG)
@example(config=({"fmu": {"vdp": {"path": "x" * 300 + ".fmu"}}}, REPOSITORY))
def test_config_fast(mirrors: dict[Path, Path], config: Config) -> None:
    fuzz_config(config, mirrors)


@pytest.mark.slow
def test_config_slow(mirrors: dict[Path, Path]) -> None:
    @slow()
    @given(config=configs)
    def fuzz_round(config: Config) -> None:
        fuzz_config(config, mirrors)

    run_for(fuzz_seconds(), fuzz_round)
