"""validate_fmu on FMUs from elsewhere (the Modelica Reference-FMUs, FMI 2.0 and 3.0), on broken
copies of them, and on one of our own; and `flexff fmu validate` on broken ones."""

import re
import tempfile
import zipfile
from pathlib import Path

import fmpy
import pytest

from flexff.cli import main
from flexff.fmu.validation import FMI3_CS_FUNCTIONS, RUN_STOPS, Problem, validate_fmu
from tests.fmu_toys import misbehaving
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
    return edited_fmu(reference(name), target, change)


def edited_fmu(source: Path, target: Path, change) -> Path:
    """A copy of the FMU `source` with `change(member, data)` applied to each member."""
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
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
                              "no co-simulation, model-exchange or scheduled-execution interface"),
    "no interface, FMI 3.0": ("fmi3/VanDerPol.fmu", description(without_interfaces),
                              "no co-simulation, model-exchange or scheduled-execution interface"),
}


def test_a_schema_violation_is_a_warning_that_names_it(tmp_path):
    """An unknown causality: the variable is neither set nor connected (a configuration that
    names it is refused), so the FMU runs; validate lists the schema's fault and fmpy's."""
    path = edited("fmi2/Dahlquist.fmu", tmp_path / "schema.fmu", description(
        lambda t: t.replace('causality="parameter"', 'causality="nonsense"')))
    problems = validate_fmu(path)
    assert [p.severity for p in problems] == ["warning", "warning"], problems
    assert "attribute 'causality'" in problems[0] and "nonsense" in problems[1]


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
        assert re.search(rf"{re.escape(str(path))}: 1 error\(s\), 0 warning\(s\)\n  - error"
                         rf"( \({RUN_STOPS}\))?: ", out), out
        assert words in out
    assert f"{good}: OK" in out


# FMI functions that misbehave as some FMUs from elsewhere do (tests.fmu_toys.misbehaving)
CRASHING_DESERIALIZE = """
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte s[], size_t n,
                                   fmi2FMUstate *state) {
    (void)c, (void)s, (void)n, (void)state;
    return *(volatile int *)0 == 0 ? fmi2OK : fmi2Error; /* a segmentation fault */
}
"""
HANGING_STEP = """
#include <unistd.h>
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean last) {
    if (t > 0.005) for (;;) sleep(1);
    return real_fmi2DoStep(c, t, h, last);
}
"""
EXITING_INSTANTIATE = """
#include <stdlib.h>
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String location, const fmi2CallbackFunctions *callbacks,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)name, (void)type, (void)guid, (void)location, (void)callbacks, (void)visible;
    (void)logging;
    exit(3);
}
"""
NANS_AFTER_A_STEP = """
#include <math.h>
static int stepped = 0;
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean last) {
    stepped = 1;
    return real_fmi2DoStep(c, t, h, last);
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    fmi2Status status = real_fmi2GetReal(c, vr, n, v);
    for (size_t i = 0; i < n && stepped; i++) v[i] = NAN;
    return status;
}
"""


def restore_off_by(relative: float) -> str:
    """Outputs read after the first restored FMU state are off by `relative`."""
    return f"""
static int restored = 0;
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {{
    restored = 1;
    return real_fmi2SetFMUstate(c, state);
}}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {{
    fmi2Status status = real_fmi2GetReal(c, vr, n, v);
    for (size_t i = 0; i < n && restored; i++) v[i] *= 1.0 + {relative!r};
    return status;
}}
"""


@pytest.fixture(scope="module")
def faulty(duffing_fmu, tmp_path_factory):
    """faulty(name, wrappers) -> the duffing toy FMU with those FMI functions (built once)."""
    folder = tmp_path_factory.mktemp("faulty")
    built = {}

    def fmu(name: str, wrappers: str) -> Path:
        if name not in built:
            built[name] = misbehaving(duffing_fmu, folder / f"{name}.fmu", wrappers)
        return built[name]

    return fmu


def test_a_crash_in_the_fmu_is_a_problem_naming_the_call(faulty):
    """The FMU crashes in fmi2DeSerializeFMUstate: the saved state (restored before) is
    still graded, and the crash is an error naming the call and the signal."""
    problems = validate_fmu(faulty("crash", CRASHING_DESERIALIZE))
    assert problems == ["fmi2DeSerializeFMUstate: the FMU crashed (SIGSEGV)"]
    assert problems[0].severity == "error"


def test_a_crash_leaves_no_files_behind(faulty, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert validate_fmu(faulty("crash", CRASHING_DESERIALIZE))
    assert list(tmp_path.iterdir()) == []


def test_an_fmu_that_hangs_is_a_timeout(faulty):
    problems = validate_fmu(faulty("hang", HANGING_STEP), timeout=3.0)
    assert problems == ["fmi2DoStep: the FMU did not return within 3 s (timeout)"]


def test_an_fmu_that_exits_is_a_problem(faulty):
    assert validate_fmu(faulty("exit", EXITING_INSTANTIATE)) == [
        "fmi2Instantiate: the FMU ended the process (exit code 3)"]


def test_a_restore_off_within_the_tolerance_is_a_warning(faulty):
    """Off by 1e-9 relative: a warning with its size by default, an error with strict."""
    path = faulty("off", restore_off_by(1e-9))
    problems = validate_fmu(path)
    assert [p.severity for p in problems] == ["warning", "warning"]
    for problem, how in zip(problems, ("saved", "serialized")):
        assert problem.startswith(f"restoring a {how} FMU state does not reproduce")
        assert problem.size == pytest.approx(1e-9, rel=1e-3)
        assert "within the FMU's tolerance 1e-06" in problem
    strict = validate_fmu(path, strict=True)
    assert [p.severity for p in strict] == ["error", "error"]
    assert all("bit for bit (largest relative difference 1e-09)" in p for p in strict)


def test_a_restore_off_beyond_the_tolerance_is_an_error(faulty):
    problems = validate_fmu(faulty("far-off", restore_off_by(1e-4)))
    assert [p.severity for p in problems] == ["error", "error"]
    assert all(p.size == pytest.approx(1e-4, rel=1e-3) for p in problems)
    assert "beyond the FMU's tolerance 1e-06" in problems[0]


def test_the_tolerance_is_the_default_experiments(faulty, tmp_path):
    """With tolerance="1e-10" in the default experiment, 1e-9 is beyond it."""
    path = edited_fmu(faulty("off", restore_off_by(1e-9)), tmp_path / "tight.fmu",
                      description(lambda t: re.sub(r"<DefaultExperiment ",
                                                   '<DefaultExperiment tolerance="1e-10" ', t)))
    assert [p.severity for p in validate_fmu(path)] == ["error", "error"]


def test_state_checks_follow_the_capability_flags(faulty, tmp_path):
    """An FMU that does not declare serialization is never asked to deserialize."""
    path = edited_fmu(faulty("crash", CRASHING_DESERIALIZE), tmp_path / "unserializable.fmu",
                      description(lambda t: t.replace('canSerializeFMUstate="true"',
                                                      'canSerializeFMUstate="false"')))
    assert validate_fmu(path) == []


def test_outputs_that_are_not_finite_are_reported(faulty):
    assert validate_fmu(faulty("nan", NANS_AFTER_A_STEP)) == [
        "outputs not finite within 20 steps of 0.001 s with default values: q_meas, q_true, "
        "v_true, a"]


def test_cli_grades_and_exits_by_severity(faulty, tmp_path, capsys):
    """0 with warnings only, 1 with an error, 2 for a path that is missing or no file."""
    off = str(faulty("off", restore_off_by(1e-9)))
    assert main(["fmu", "validate", off]) == 0
    out = capsys.readouterr().out
    assert f"{off}: 0 error(s), 2 warning(s)\n  - warning: restoring a saved" in out
    assert main(["fmu", "validate", "--strict", off]) == 1
    assert "  - error: restoring a saved FMU state" in capsys.readouterr().out
    crash = str(faulty("crash", CRASHING_DESERIALIZE))
    assert main(["fmu", "validate", off, crash]) == 1
    assert "  - error: fmi2DeSerializeFMUstate: the FMU crashed (SIGSEGV)" in \
        capsys.readouterr().out
    assert main(["fmu", "validate", crash, str(tmp_path / "missing.fmu"), str(tmp_path)]) == 2
    assert capsys.readouterr().err == (f"flexff: error: {tmp_path / 'missing.fmu'}: no such "
                                       f"file\nflexff: error: {tmp_path}: not a file\n")


def test_severities_are_checked():
    with pytest.raises(ValueError, match="severity 'fatal'"):
        Problem("x", "fatal")


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
