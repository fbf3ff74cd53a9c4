"""The two classes of description fault (fmu.description_faults), on Reference-FMUs whose
modelDescription.xml is edited as third-party exporters write them.

A fault that changes nothing at run time (an empty or partial <InitialUnknowns>, an Enumeration
declared continuous, an input without a start value) lets the FMU run as FMPy runs it: the
record equals the unedited FMU's bit for bit, one warning says so, run.json lists the faults;
`strict` refuses it. A fault that would make the record or the wiring wrong (a duplicate name,
a value reference out of range, one value reference for two types in FMI 3.0) stops a run
before it starts, in one line naming the fault."""

import json
import re
import warnings

import fmpy
import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.config import load_config, parse_config, with_strict
from flexff.cosim.config_error import ConfigError
from flexff.cosim.run import run_config, simulate_config
from flexff.cosim.ssp import export_ssp
from flexff.fmu.description_faults import DescriptionWarning
from flexff.fmu.importer import FmuError, read_fmu
from flexff.fmu.validation import RUN_STOPS, RUN_WARNS, validate_fmu
from tests.fmu.test_validation import description, edited, reference


def _drop(pattern: str):
    return lambda t: re.sub(pattern, "", t, flags=re.S)


def _variability(name: str, value: str):
    """Give the variable `name` the variability `value` (FMI 2.0 and 3.0 layouts)."""
    def edit(text: str) -> str:
        head = re.search(rf'<\w+ name="{re.escape(name)}"[^>]*?(?=/?>)', text)
        assert head, name
        tag = re.sub(r' variability="\w+"', "", head.group(0)) + f' variability="{value}"'
        return text.replace(head.group(0), tag, 1)
    return edit


def _no_start(name: str):
    """Remove the start value of the variable `name` (FMI 2.0: on its type element)."""
    def edit(text: str) -> str:
        at = text.index(f'name="{name}"')
        end = text.index("/>", at)
        return text[:at] + re.sub(r' start="[^"]*"', "", text[at:end], count=1) + text[end:]
    return edit


# case: (Reference-FMU, edit, words of the fault); each changes nothing at run time
WARNINGS = {
    "no InitialUnknowns, FMI 2.0": ("fmi2/VanDerPol.fmu",
                                    _drop(r"\s*<InitialUnknowns>.*?</InitialUnknowns>"),
                                    "InitialUnknowns does not contain the expected set"),
    "partial InitialUnknowns, FMI 2.0": ("fmi2/VanDerPol.fmu",
                                         _drop(r'\s*<Unknown index="5" dependencies="2 4 6"'
                                               r'[^>]*/>'),
                                         "InitialUnknowns does not contain the expected set"),
    "no InitialUnknowns, FMI 3.0": ("fmi3/VanDerPol.fmu", _drop(r"\s*<InitialUnknown [^>]*/>"),
                                    "InitialUnknowns does not contain the expected set"),
    "continuous Enumeration, FMI 2.0": ("fmi2/Feedthrough.fmu",
                                        _variability("Enumeration_input", "continuous"),
                                        'must have variability != "continuous"'),
    "continuous Enumeration, FMI 3.0": ("fmi3/Feedthrough.fmu",
                                        _variability("Enumeration_input", "continuous"),
                                        'must have variability != "continuous"'),
    "input without start, FMI 2.0": ("fmi2/Feedthrough.fmu",
                                     _no_start("Float64_continuous_input"), "has no start value"),
    "input without start, FMI 3.0": ("fmi3/Feedthrough.fmu",
                                     _no_start("Float64_continuous_input"), "has no start value"),
}
# case: (Reference-FMU, edit, words of the one line)
FATAL = {
    "duplicate name": ("fmi2/VanDerPol.fmu", lambda t: t.replace('name="x1"', 'name="x0"'),
                       'the variable name "x0" is given 2 times: two variables share this '
                       'name'),
    "negative value reference": ("fmi2/VanDerPol.fmu",
                                 lambda t: t.replace('valueReference="5"', 'valueReference="-5"'),
                                 'the variable "mu" has the value reference -5: a value '
                                 'reference is an unsigned 32-bit integer'),
    "one value reference, two types (FMI 3.0)": (
        "fmi3/Feedthrough.fmu",
        lambda t: t.replace("</ModelVariables>", '<Int32 name="counter" valueReference="7" '
                            'causality="local" variability="discrete" initial="exact" '
                            'start="0"/></ModelVariables>'),
        'the variables "Float64_continuous_input" (Float64), "counter" (Int32) share the '
        'value reference 7'),
}


def _faulty(case: str, cases: dict, folder):
    name, edit, words = cases[case]
    path = edited(name, folder / f"{name.replace('/', '_')}", description(edit))
    return name, path, words


def _config(path, folder, **keys) -> str:
    """A configuration of the FMU at `path` alone, its inputs at their start values."""
    table = "".join(f"{k} = {json.dumps(v)}\n" for k, v in keys.items())
    text = (f'[run]\nstep = 0.01\nstop = 1.0\n[fmu.m]\npath = "{path}"\n'
            f'unconnected = "start"\n{table}')
    (folder / "run.toml").write_text(text)
    return str(folder / "run.toml")


@pytest.mark.parametrize("case", WARNINGS)
def test_a_harmless_fault_runs_bit_for_bit_with_one_warning(tmp_path, case):
    name, faulty, words = _faulty(case, WARNINGS, tmp_path)
    assert any(words in str(f) for f in read_fmu(faulty).faults)
    with pytest.warns(DescriptionWarning) as said:
        config = load_config(_config(faulty, tmp_path))
        metrics = run_config(config, tmp_path / "out")
    assert len(said) == 1, [str(w.message) for w in said]
    assert re.match(rf"fmu\.m: {faulty.name}: its model description has faults that change no "
                    rf"run, so it runs as FMPy runs it: .*strict = true refuses it",
                    str(said[0].message))
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert any(words in fault for fault in run["description_faults"]["m"])
    assert metrics["real_time_factor"] > 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the unedited FMU has no fault
        plain = simulate_config(parse_config({"run": {"step": 0.01, "stop": 1.0}, "fmu": {
            "m": {"path": str(reference(name)), "unconnected": "start"}}}))
    with pytest.warns(DescriptionWarning):
        again = simulate_config(parse_config({"run": {"step": 0.01, "stop": 1.0}, "fmu": {
            "m": {"path": str(faulty), "unconnected": "start"}}}))
    assert list(again.signals) == list(plain.signals)
    for signal in plain.signals:
        assert np.array_equal(again[signal], plain[signal]), signal


@pytest.mark.parametrize("case", WARNINGS)
def test_strict_refuses_a_harmless_fault(tmp_path, capsys, case):
    _, faulty, words = _faulty(case, WARNINGS, tmp_path)
    with pytest.raises(FmuError, match="strict = true refuses"):
        read_fmu(faulty, strict=True)
    with pytest.raises(ConfigError, match=re.escape(words)) as refused:
        load_config(_config(faulty, tmp_path, strict=True))
    assert refused.value.key == "fmu.m.path"
    config = _config(faulty, tmp_path)
    for argv in (["run", config, "--strict"], ["run", _config(faulty, tmp_path, strict=True)]):
        code = main([*argv, "-o", str(tmp_path / "out")])
        err = capsys.readouterr().err
        assert code == 2, err
        assert len(err.splitlines()) == 1 and words in err and "strict" in err, err
        assert not (tmp_path / "out" / "run.json").exists()


def test_strict_is_kept_in_the_general_form(tmp_path):
    _, faulty, _ = _faulty("no InitialUnknowns, FMI 2.0", WARNINGS, tmp_path)
    with pytest.warns(DescriptionWarning):
        config = load_config(_config(faulty, tmp_path))
    assert not config.fmus[0].strict
    with pytest.raises(ConfigError, match="strict = true refuses"):
        with_strict(config)


@pytest.mark.parametrize("case", FATAL)
def test_a_fault_that_would_make_the_run_wrong_stops_it(tmp_path, capsys, case):
    _, faulty, words = _faulty(case, FATAL, tmp_path)
    problems = validate_fmu(faulty)
    assert any(words in p and p.in_run == RUN_STOPS and p.severity == "error"
               for p in problems), problems
    with pytest.raises(FmuError, match="a run would be wrong"):
        read_fmu(faulty)
    code = main(["run", _config(faulty, tmp_path), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err  # bad input
    assert len(err.splitlines()) == 1 and words in err, err
    assert err.startswith(f"flexff: error: {tmp_path / 'run.toml'}: fmu.m.path: {faulty}: "
                          f"modelDescription.xml: ")
    assert not (tmp_path / "out" / "run.json").exists()


def test_one_value_reference_for_two_types_is_legal_in_fmi2(tmp_path):
    """FMI 2.0 gives each base type value references of its own (fmi2GetReal, ...)."""
    faulty = edited("fmi2/Feedthrough.fmu", tmp_path / "f.fmu", description(
        lambda t: t.replace('name="Int32_input" valueReference="19"',
                            'name="Int32_input" valueReference="7"')))
    assert read_fmu(faulty).faults == ()


def test_validate_says_what_each_fault_does_to_a_run(tmp_path, capsys):
    _, harmless, words = _faulty("continuous Enumeration, FMI 2.0", WARNINGS, tmp_path)
    problems = validate_fmu(harmless)
    assert [p.severity for p in problems] == ["warning"]
    assert problems[0].in_run == RUN_WARNS and words in problems[0]
    assert [p.severity for p in validate_fmu(harmless, strict=True)] == ["error"]
    assert main(["fmu", "validate", str(harmless)]) == 0
    out = capsys.readouterr().out
    assert f"{harmless}: 0 error(s), 1 warning(s)\n  - warning ({RUN_WARNS}): " in out
    assert main(["fmu", "validate", "--strict", str(harmless)]) == 1
    capsys.readouterr()


def test_fmpy_runs_a_harmless_fault_as_flexff_does(tmp_path):
    _, faulty, _ = _faulty("no InitialUnknowns, FMI 3.0", WARNINGS, tmp_path)
    with pytest.warns(DescriptionWarning):
        ours = simulate_config(load_config(_config(faulty, tmp_path)))
    theirs = fmpy.simulate_fmu(str(faulty), fmi_type="CoSimulation", step_size=0.01,
                               output_interval=0.01, stop_time=1.0, output=["x0", "x1"])
    for name in ("x0", "x1"):
        assert np.array_equal(ours[f"m.{name}"], theirs[name]), name


def test_an_ssp_whose_fmu_has_a_harmless_fault_runs(tmp_path, capsys):
    _, faulty, words = _faulty("partial InitialUnknowns, FMI 2.0", WARNINGS, tmp_path)
    with pytest.warns(DescriptionWarning):
        ssp = export_ssp(load_config(_config(faulty, tmp_path)), tmp_path / "system.ssp")
    assert main(["run", str(ssp), "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "flexff: warning: " in err and "change no run" in err, err
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert any(words in fault for fault in run["description_faults"]["m"])
