"""One run model: the same rules on every path into a run, and nothing re-read downstream.

Each test holds one rule that used to be written several times, or one stage that used to
re-read what an earlier one had checked: what may be set (one predicate for the parser, the SSP
reader, the master and the learning loop), how long a run may be (one rule for TOML and SSP),
the model descriptions (read once, by resolve), the reference (sampled once per process) and
the configuration itself (checked whichever way it was made).
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

import flexff.cosim.master
import flexff.cosim.references
import flexff.fmu.importer
from flexff.cosim.config import checked, load_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.references import build_reference
from flexff.cosim.run import simulate
from flexff.cosim.scenario import resolve
from flexff.cosim.ssp import export_ssp, load_ssp
from flexff.fmu.errors import InputError
from flexff.fmu.importer import SETTABLE, read_fmu
from tests.cosim.test_ssp import rewritten
from tests.cosim.test_typed_connections import config_file, feedthrough
from tests.helpers import REFERENCE_FMUS

FEEDTHROUGH = REFERENCE_FMUS / "fmi3" / "Feedthrough.fmu"
OUTPUT = "Float64_continuous_output"


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))


def known(message: str) -> list[str]:
    """The names an error lists as `(known: a, b, ...)`."""
    match = re.search(r"\(known: ([^)]*)\)", message)
    assert match, message
    return match.group(1).split(", ")


def test_one_rule_for_what_may_be_set(tmp_path):
    """The parser and the master (Python code that skips the parser) refuse an output as a
    start value with the same list of what may be set: the FMU's parameters and inputs."""
    info = read_fmu(FEEDTHROUGH)
    expected = [n for n, v in info.variables.items() if v.causality in SETTABLE]
    assert "Float64_continuous_input" in expected and OUTPUT not in expected
    with pytest.raises(ConfigError) as parsed:
        load_config(config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3, **{OUTPUT: 1.0})},
                                []))
    assert parsed.value.key == f"fmu.a.parameters.{OUTPUT}"
    with pytest.raises(InputError) as direct:
        Master([ResolvedFmu("a", FEEDTHROUGH, {OUTPUT: 1.0})], [], 0.01)
    assert known(str(parsed.value)) == known(str(direct.value)) == expected


def test_one_rule_for_a_runs_length(tmp_path):
    """A stop time that is not a whole number of steps is refused from TOML and from a plain
    SSP alike, each naming its own key."""
    path = config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3)}, [])
    ssp = export_ssp(load_config(path), tmp_path / "system.ssp")
    bad = rewritten(ssp, tmp_path / "bad.ssp", lambda text: re.sub(
        r'stopTime="[^"]*"', 'stopTime="0.305"', text.replace(
            text[text.index("<flexff:Configuration>"):text.index("</flexff:Configuration>")
                 + len("</flexff:Configuration>")], "")))
    with pytest.raises(ConfigError, match="not a whole number of steps") as from_ssp:
        load_ssp(bad)
    assert from_ssp.value.key.startswith("ssd:DefaultExperiment")
    path.write_text(path.read_text().replace("stop = 0.3", "stop = 0.305"))
    with pytest.raises(ConfigError, match="not a whole number of steps") as from_toml:
        load_config(path)
    assert from_toml.value.key == "run.stop"


def test_nothing_is_read_again_after_resolve(tmp_path, monkeypatch):
    """The master loads the FMUs with the model descriptions the resolved scenario carries:
    with every reader of model descriptions broken after resolve, the run still runs."""
    path = config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3), "b": feedthrough(2)}, [
        {"from": "u", "to": "a.Float64_continuous_input"},
        {"from": "a.Float64_continuous_output", "to": "b.Float64_continuous_input",
         "gain": 2.0}], source=[{"kind": "constant", "values": {"u": 0.25}}])
    scenario = resolve(load_config(path), tmp_path / "build")

    def broken(*args, **kwargs):
        raise AssertionError("a model description was read again after resolve")

    monkeypatch.setattr(flexff.fmu.importer, "read_fmu", broken)
    monkeypatch.setattr(flexff.cosim.master, "read_fmu", broken)
    monkeypatch.setattr(flexff.fmu.importer, "read_model_description", broken)
    recording = simulate(scenario, progress=False)
    assert np.all(recording.signals["b.Float64_continuous_output"] == 0.5)


def test_a_reference_is_sampled_once_per_process(monkeypatch):
    """Two runs on the same reference share one sampling (read-only arrays); another step
    samples anew."""
    calls = []
    registered = flexff.cosim.references._registered

    def counted(kind):
        found = registered(kind)
        return replace(found, build=lambda *args: calls.append(args) or found.build(*args))

    monkeypatch.setattr(flexff.cosim.references, "_registered", counted)
    monkeypatch.setattr(flexff.cosim.references, "_SAMPLED", type(
        flexff.cosim.references._SAMPLED)())
    first = build_reference("thesis-eval", {}, 1e-3)
    second = build_reference("thesis-eval", {}, 1e-3)
    assert first is second and len(calls) == 1 and not first.x.flags.writeable
    build_reference("thesis-eval", {}, 2e-3)
    assert len(calls) == 2


def test_a_configuration_changed_in_code_is_checked_again(tmp_path):
    """A copy changed with dataclasses.replace is not the parser's: resolve checks it as its
    file would be, and the parser's own object passes through untouched."""
    path = config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3)}, [])
    config = load_config(path)
    assert config.checked and checked(config) is config
    (a,) = config.fmus
    edited = replace(config, fmus=(replace(a, parameters={OUTPUT: 1.0}),))
    assert not edited.checked
    with pytest.raises(ConfigError) as error:
        resolve(edited, tmp_path / "build")
    assert error.value.key == f"fmu.a.parameters.{OUTPUT}"
    fine = replace(config, stop=0.2)
    assert checked(fine).checked and checked(fine).steps == 20


def test_a_plain_ssp_goes_through_the_parser(tmp_path):
    """An SSP without flexff's annotation is read into a RunConfig and checked by the parser
    (its connections keep their `ssd:Connection[k]` names for later errors)."""
    path = config_file(tmp_path, "jacobi", {"a": feedthrough(3), "b": feedthrough(3)}, [
        {"from": "a.Float64_continuous_output", "to": "b.Float64_continuous_input"}])
    ssp = export_ssp(load_config(path), tmp_path / "system.ssp")
    plain = load_ssp(rewritten(ssp, tmp_path / "plain.ssp", lambda text: re.sub(
        r"\s*<flexff:Configuration>.*</flexff:Configuration>", "", text, flags=re.S)))
    assert plain.checked and [c.key for c in plain.connections] == ["ssd:Connection[1]"]


def test_one_time_table_reader_for_references_and_sources(tmp_path):
    """A reference CSV and a [[source]] CSV are read by the same reader: `time` names the
    time column in both, and the old `t` still reads, to the same values."""
    rows = "0,0.0,0.0\n0.1,0.01,0.0\n0.2,0.01,0.01\n"  # 21 points at the 0.01 s step
    signals = {}
    for header in ("time", "t"):
        (tmp_path / f"{header}.csv").write_text(f"{header},x_ref,y_ref\n{rows}")
        reference = load_config(config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3)}, [],
                                            reference={"kind": "csv", "path": f"{header}.csv"}))
        source = load_config(config_file(tmp_path, "gauss-seidel", {"a": feedthrough(3)}, [
            {"from": "x_ref", "to": "a.Float64_continuous_input"}],
            source=[{"kind": "csv", "path": f"{header}.csv"}]))
        with_source = simulate(resolve(source, tmp_path / "build"), progress=False)
        signals[header] = (build_reference("csv", reference.reference.options, 1e-3).x,
                           with_source.signals["a.Float64_continuous_output"])
    assert np.array_equal(signals["time"][0], signals["t"][0])
    assert np.array_equal(signals["time"][1], signals["t"][1])
    assert signals["t"][1][-1] == 0.01
