"""validate_fmu on FMUs from elsewhere (the Modelica Reference-FMUs, FMI 2.0 and 3.0), on broken
copies of them, and on one of our own; and `flexff fmu validate` on broken ones."""

import math
import re
import zipfile
from pathlib import Path

import fmpy
import pytest
from fmpy.fmi3 import FMU3Slave

from flexff.cli import main
from flexff.fmu.importer import FmuInstance
from flexff.fmu.validation import FMI3_CS_FUNCTIONS, validate_fmu
from tests.helpers import REFERENCE_FMUS

REFERENCE_NAMES = [f"fmi{v}/{m}.fmu" for v in (2, 3) for m in ("Dahlquist", "Feedthrough",
                                                                "VanDerPol")]


def reference(name: str) -> Path:
    """A Reference-FMU of the repository's copy; a missing one fails the test."""
    path = REFERENCE_FMUS / name
    assert path.is_file(), f"{path} is missing"
    return path


def edited(name: str, target: Path, change) -> Path:
    """A copy of a Reference-FMU with `change(member, data)` applied to each member (None drops
    it)."""
    with zipfile.ZipFile(reference(name)) as src, zipfile.ZipFile(target, "w") as dst:
        for item in src.infolist():
            data = change(item.filename, src.read(item))
            if data is not None:
                dst.writestr(item, data)
    return target


def description(edit):
    """A `change` for `edited` that edits modelDescription.xml as text."""
    return lambda member, data: (edit(data.decode()).encode()
                                 if member == "modelDescription.xml" else data)


def without_binaries(member, data):
    return None if member.startswith("binaries/") else data


def garbage_binaries(member, data):
    return b"not a shared object" if member.startswith("binaries/") and data else data


def zero_token(text: str) -> str:
    return re.sub(r'(guid|instantiationToken)="[^"]*"',
                  r'\1="{00000000-0000-0000-0000-000000000000}"', text)


def without_interfaces(text: str) -> str:
    """Neither co-simulation nor model exchange: nothing to run."""
    for tag in ("CoSimulation", "ModelExchange"):
        text = re.sub(rf"<{tag}[^>]*/>|<{tag}.*?</{tag}>", "", text, count=1, flags=re.S)
    return text


@pytest.mark.parametrize("name", REFERENCE_NAMES)
def test_reference_fmus_pass(name):
    assert validate_fmu(reference(name)) == []


def test_our_own_fmu_passes(pi_fmu):
    assert validate_fmu(pi_fmu) == []


BROKEN = {  # case: (source FMU, change, words the problem must contain)
    "malformed description": ("fmi2/VanDerPol.fmu", description(lambda t: t[:len(t) // 2]),
                              "cannot read modelDescription.xml"),
    "no description": ("fmi3/Dahlquist.fmu",
                       lambda m, d: None if m == "modelDescription.xml" else d,
                       "cannot read modelDescription.xml"),
    "schema violation": ("fmi2/Dahlquist.fmu",
                         description(lambda t: t.replace('causality="parameter"',
                                                         'causality="nonsense"')),
                         "nonsense"),
    "binary removed, FMI 2.0": ("fmi2/VanDerPol.fmu", without_binaries,
                                f"no binary for this platform (binaries/{fmpy.platform}/"
                                "VanDerPol.so is missing)"),
    "binary removed, FMI 3.0": ("fmi3/VanDerPol.fmu", without_binaries,
                                f"no binary for this platform (binaries/{fmpy.platform_tuple}/"
                                "VanDerPol.so is missing)"),
    "garbage binary, FMI 2.0": ("fmi2/Feedthrough.fmu", garbage_binaries,
                                "Failed to load shared library"),
    "garbage binary, FMI 3.0": ("fmi3/Feedthrough.fmu", garbage_binaries,
                                "Failed to load shared library"),
    "instantiate returns NULL, FMI 2.0": ("fmi2/Dahlquist.fmu", description(zero_token),
                                          "cannot instantiate: Failed to instantiate model "
                                          "([Error] Wrong GUID.)"),
    "instantiate returns NULL, FMI 3.0": ("fmi3/Dahlquist.fmu", description(zero_token),
                                          "Wrong instantiationToken"),
    "no interface, FMI 2.0": ("fmi2/VanDerPol.fmu", description(without_interfaces),
                              "neither a co-simulation nor a model-exchange interface"),
    "no interface, FMI 3.0": ("fmi3/VanDerPol.fmu", description(without_interfaces),
                              "neither a co-simulation nor a model-exchange interface"),
}


@pytest.fixture
def broken(tmp_path) -> dict[str, tuple[Path, str]]:
    """Every broken FMU (not-a-zip included), with the words its problem must contain."""
    junk = tmp_path / "junk.fmu"
    junk.write_bytes(b"PK\x03\x04 but not a zip archive")
    fmus = {"not a zip": (junk, "is not an FMU")}
    for i, (case, (name, change, words)) in enumerate(BROKEN.items()):
        fmus[case] = (edited(name, tmp_path / f"broken{i}.fmu", change), words)
    return fmus


@pytest.mark.parametrize("case", ["not a zip", *BROKEN])
def test_broken_fmus_are_reported(broken, case):
    path, words = broken[case]
    problems = validate_fmu(path)
    assert problems and all(isinstance(p, str) for p in problems)
    assert any(words in p for p in problems), problems


def test_cli_lists_the_problems_without_a_traceback(broken, capsys):
    """Every broken FMU in one call, then a good one: a failed load leaves nothing behind."""
    paths = [str(path) for path, _ in broken.values()]
    good = reference("fmi3/VanDerPol.fmu")
    assert main(["fmu", "validate", *paths, str(good)]) != 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    for path, words in broken.values():
        assert re.search(rf"{re.escape(str(path))}: \d+ problem\(s\)\n  - ", out)
        assert words in out
    assert f"{good}: OK" in out


def test_a_state_that_does_not_restore_is_reported(monkeypatch):
    """Restoring the state also changes an input (value reference 7) of the feedthrough."""
    restore = FMU3Slave.setFMUState

    def restore_badly(self, state):
        restore(self, state)
        self.setFloat64([7], [1.0])

    monkeypatch.setattr(FMU3Slave, "setFMUState", restore_badly)
    assert validate_fmu(reference("fmi3/Feedthrough.fmu")) == [
        f"restoring a {how} FMU state does not reproduce the outputs of the uninterrupted run"
        for how in ("saved", "serialized")]


def test_state_checks_follow_the_capability_flags(tmp_path, monkeypatch):
    path = edited("fmi3/VanDerPol.fmu", tmp_path / "stateless.fmu", description(
        lambda t: t.replace('canGetAndSetFMUState="true"', 'canGetAndSetFMUState="false"')))
    monkeypatch.setattr(FMU3Slave, "getFMUState", lambda self: pytest.fail("state asked for"))
    assert validate_fmu(path) == []


def test_outputs_that_are_not_finite_are_reported(monkeypatch):
    monkeypatch.setattr(FmuInstance, "get", lambda self, names: [math.nan for _ in names])
    assert validate_fmu(reference("fmi2/Dahlquist.fmu")) == [
        "outputs not finite within 20 steps of 0.1 s with default values: x"]


def test_fmi3_functions_are_those_of_the_header():
    """The co-simulation set of fmi3Functions.h: everything but the other interfaces'."""
    header = (Path(fmpy.__file__).parent / "c-code" / "fmi3Functions.h").read_text()
    exported = re.findall(r"^FMI3_Export \w+TYPE\s+(\w+);", header, flags=re.M)
    model_exchange = header.rindex("Functions for Model Exchange")  # past the #defines
    co_simulation = header.rindex("Functions for Co-Simulation")
    others = {"fmi3InstantiateModelExchange", "fmi3InstantiateScheduledExecution",
              "fmi3ActivateModelPartition"}
    others |= set(re.findall(r"^FMI3_Export \w+TYPE\s+(\w+);",
                             header[model_exchange:co_simulation], flags=re.M))
    assert sorted(FMI3_CS_FUNCTIONS) == sorted(set(exported) - others)
