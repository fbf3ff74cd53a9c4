"""Fuzzing SSP archives (cosim.ssp.load_ssp, `flexff run FILE.ssp`): an exported SSP of two
Reference-FMUs with its SystemStructure.ssd's elements and attributes edited, its flexff
annotation's configuration text mutated, an FMU in it replaced or damaged, the archive's bytes
mutated, and garbage (tests/fuzz/harness.py)."""

from __future__ import annotations

import io
import itertools
import shutil
import zipfile
from pathlib import Path

import pytest
import tomli_w
from hypothesis import given
from hypothesis import strategies as st
from lxml import etree

from flexff.cosim.config import load_config
from flexff.cosim.ssp import NS, SSD, export_ssp, load_ssp
from flexff.fmu.errors import InputError
from tests.fuzz.harness import check, fast, fuzz_seconds, run_for, slow
from tests.fuzz.mutations import XML_TEXTS, garbage, mutated_bytes, mutated_text, mutated_xml
from tests.helpers import REFERENCE_FMUS

CONFIG = {"run": {"step": 0.01, "stop": 2.0, "algorithm": "jacobi"},
          "fmu": {"vdp": {"path": str(REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"),
                          "parameters": {"mu": 1.5}},
                  "ft": {"path": str(REFERENCE_FMUS / "fmi3" / "Feedthrough.fmu"),
                         "unconnected": "start"}},
          "connection": [{"from": "vdp.x0", "to": "ft.Float64_continuous_input",
                          "gain": 2.0, "offset": 0.5}]}
CONFIGURATION = "ssd:DefaultExperiment//flexff:Configuration"
_files = itertools.count()


@pytest.fixture(scope="module")
def members(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The members of the valid SSP archive the fuzzer mutates."""
    folder = tmp_path_factory.mktemp("ssp")
    (folder / "system.toml").write_text(tomli_w.dumps(CONFIG))
    path = export_ssp(load_config(folder / "system.toml"), folder / "system.ssp")
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def _zip(members: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


def _with_configuration(ssd: bytes, text: str) -> bytes:
    """The SSD with its flexff annotation's configuration replaced by `text`."""
    root = etree.fromstring(ssd)
    element = root.find(CONFIGURATION, NS)
    assert element is not None
    element.text = "".join(c for c in text if c.isprintable() or c in "\n\t")  # XML's
    return bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))


def archives(members: dict[str, bytes]) -> st.SearchStrategy[bytes]:
    """SSP archives near the valid one (module doc), and garbage."""
    root = etree.fromstring(members[SSD])
    tags = sorted({e.tag for e in root.iter() if isinstance(e.tag, str)})
    attributes = sorted({a for e in root.iter() for a in e.attrib})
    values = [*XML_TEXTS, *members, *(e.get(a, "") for e in root.iter() for a in e.attrib),
              "resources", "resources/../../x.fmu", "1e-3", "0", "-1", "1e308"]
    configuration = root.find(CONFIGURATION, NS)
    assert configuration is not None and configuration.text is not None
    fmus = [name for name in members if name.endswith(".fmu")]
    ssds = st.one_of(
        mutated_xml(root, tags, attributes, values),
        mutated_text(configuration.text).map(lambda t: _with_configuration(members[SSD], t)),
        mutated_bytes(members[SSD]))
    replaced = st.tuples(st.sampled_from(fmus), st.one_of(
        st.sampled_from([m for name, m in members.items() if name != SSD]), garbage(),
        st.sampled_from(fmus).flatmap(lambda name: mutated_bytes(members[name]))))
    return st.one_of(
        ssds.map(lambda ssd: _zip({**members, SSD: ssd})),
        replaced.map(lambda r: _zip({**members, r[0]: r[1]})),
        st.sampled_from(fmus).map(lambda name: _zip({n: m for n, m in members.items()
                                                     if n != name})),
        mutated_bytes(_zip(members)),
        garbage())


def fuzz_ssp(folder: Path, archive: bytes) -> None:
    """The property for one SSP file; the FMU cache (FLEXFF_CACHE) emptied after it."""
    path = folder / f"fuzz-{next(_files)}.ssp"
    path.write_bytes(archive)
    check(lambda: load_ssp(path))
    path.unlink()
    shutil.rmtree(folder / "cache", ignore_errors=True)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh FMU cache, where load_ssp extracts archives."""
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))
    return tmp_path


@pytest.mark.filterwarnings("ignore::UserWarning")  # a changed system's annotation is ignored
@fast(examples=25)
@given(data=st.data())
def test_ssp_fast(cache: Path, members: dict[str, bytes], data: st.DataObject) -> None:
    fuzz_ssp(cache, data.draw(archives(members)))


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_ssp_slow(cache: Path, members: dict[str, bytes]) -> None:
    strategy = archives(members)

    @slow()
    @given(archive=strategy)
    def fuzz_round(archive: bytes) -> None:
        fuzz_ssp(cache, archive)

    run_for(fuzz_seconds(), fuzz_round)


def test_a_relative_namespace_reads_as_a_plain_system(cache: Path,
                                                       members: dict[str, bytes]) -> None:
    """Found by the fuzzer: an SSD whose namespace URI is relative could not be canonicalized
    (lxml's C14NError) when it was compared with the configuration it carries; now the
    annotation is ignored with a warning and the system read as plain SSP."""
    ssd = members[SSD].replace(b'xmlns:ssv="http://ssp-standard.org',
                               b'xmlns:ssv="//ssp-standard.org')
    assert ssd != members[SSD]
    path = cache / "relative.ssp"
    path.write_bytes(_zip({**members, SSD: ssd}))
    with pytest.warns(UserWarning, match="no longer the flexff configuration it carries"):
        config = load_ssp(path)
    assert config.fmus


def test_archive_without_its_first_byte(cache: Path, members: dict[str, bytes]) -> None:
    """Found by the fuzzer: an archive cut by its first byte made zipfile seek before the
    file's start, an OSError (EINVAL) out of fmu.archive.extract_archive; now one line
    naming the damaged member."""
    path = cache / "cut.ssp"
    path.write_bytes(_zip(members)[1:])
    with pytest.raises(InputError, match=r"member 'SystemStructure\.ssd' is damaged"):
        load_ssp(path)
