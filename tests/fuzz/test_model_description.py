"""Fuzzing FMUs' modelDescription.xml (fmu.importer.read_fmu, which every run, validation and
SSP import reads an FMU with, and a run configuration naming the FMU): the Modelica
Reference-FMUs' descriptions with elements removed, repeated or renamed and attributes given
odd values, their XML text mutated, damaged archives and garbage (tests/fuzz/harness.py)."""

from __future__ import annotations

import io
import itertools
import zipfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from lxml import etree

from flexff.cosim.config import parse_config
from flexff.fmu.importer import FmuError, read_fmu
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import XML_TEXTS, garbage, mutated_bytes, mutated_text, mutated_xml
from tests.helpers import REFERENCE_FMUS

DESCRIPTIONS = [zipfile.ZipFile(path).read("modelDescription.xml").decode()
                for path in sorted(REFERENCE_FMUS.glob("fmi*/*.fmu"))]
TREES = [etree.fromstring(text.encode()) for text in DESCRIPTIONS]
TAGS = sorted({e.tag for tree in TREES for e in tree.iter() if isinstance(e.tag, str)})
ATTRIBUTES = sorted({a for tree in TREES for e in tree.iter() for a in e.attrib})
# odd attribute values, and the ones FMI gives meaning to
VALUES = [*XML_TEXTS, "2.0", "3.0", "1.0", "input", "output", "parameter", "local",
          "independent", "fixed", "tunable", "discrete", "continuous", "exact", "calculated",
          "approx", "1 2 3", "0", "4294967296", "-5", "1e-2", "{00000000}"]
_files = itertools.count()


def _archive(description: bytes) -> bytes:
    """An FMU archive holding only `description` as its modelDescription.xml."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("modelDescription.xml", description)
    return buffer.getvalue()


descriptions = st.one_of(
    st.sampled_from(TREES).flatmap(lambda tree: mutated_xml(tree, TAGS, ATTRIBUTES, VALUES)),
    st.sampled_from(DESCRIPTIONS).flatmap(mutated_text).map(str.encode),
    garbage())
archives = st.one_of(
    descriptions.map(_archive),
    st.sampled_from(DESCRIPTIONS).map(str.encode).map(_archive).flatmap(mutated_bytes))


def fuzz_fmu(folder: Path, archive: bytes) -> None:
    """The property for one FMU file: read checked and unchecked, and named by a run."""
    path = folder / f"fuzz-{next(_files)}.fmu"
    path.write_bytes(archive)
    check(lambda: read_fmu(path))
    check(lambda: read_fmu(path, checked=False))
    check(lambda: parse_config({"fmu": {"m": {"path": str(path), "unconnected": "start"}}},
                               origin="fuzz.toml"))
    path.unlink()


@fast()
@given(archive=archives)
def test_model_description_fast(tmp_path: Path, archive: bytes) -> None:
    fuzz_fmu(tmp_path, archive)


@pytest.mark.slow
def test_model_description_slow(tmp_path: Path) -> None:
    @slow()
    @given(archive=archives)
    def fuzz_round(archive: bytes) -> None:
        fuzz_fmu(tmp_path, archive)

    run_for(fuzz_seconds(), fuzz_round)


def test_experiment_time_not_a_number(tmp_path: Path) -> None:
    """Found by the fuzzer: a DefaultExperiment startTime of " ", read unchecked (as `flexff
    fmu validate` reads), was a ValueError from float(); now one line naming the attribute."""
    description = DESCRIPTIONS[0].replace('startTime="0"', 'startTime=" "')
    assert description != DESCRIPTIONS[0]
    path = tmp_path / "blank.fmu"
    path.write_bytes(_archive(description.encode()))
    with pytest.raises(FmuError, match="DefaultExperiment startTime = ' ' is not a number"):
        read_fmu(path, checked=False)
