"""flexff fmu compare: each FMU alone in flexff and in FMPy on its default experiment, the
largest difference per output, a verdict and an exit code."""

import math
import re
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim import compare
from flexff.cosim.compare import compare_fmu, difference, experiment
from flexff.fmu.importer import read_fmu
from tests.helpers import REFERENCE_FMUS

REFERENCES = sorted(REFERENCE_FMUS.glob("fmi*/*.fmu"))


@pytest.mark.parametrize("path", REFERENCES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_the_reference_fmus_are_bit_equal_to_fmpy(path):
    comparison = compare_fmu(path)
    assert comparison.points > 10 and comparison.outputs
    assert all(o.absolute == 0.0 == o.relative for o in comparison.outputs)
    assert comparison.agrees() and comparison.verdict().startswith("bit-equal")


def with_experiment(tmp_path: Path, attributes: str) -> Path:
    """Dahlquist (FMI 2.0) with its default experiment replaced by `attributes`."""
    target = tmp_path / "Dahlquist.fmu"
    with zipfile.ZipFile(REFERENCE_FMUS / "fmi2" / "Dahlquist.fmu") as src, \
            zipfile.ZipFile(target, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = re.sub(rb"<DefaultExperiment[^>]*/>",
                              f"<DefaultExperiment {attributes}/>".encode(), data)
            dst.writestr(item, data)
    return target


@pytest.mark.parametrize("attributes", ['startTime="0" stopTime="10" stepSize="0.001"',
                                        'stopTime="3"', ""])
def test_the_experiment_is_fmpys(tmp_path, attributes):
    """The step FMPy picks itself (its result's spacing): a default-experiment step doubled
    to at most 1000 steps, else its automatic interval; stop 1 s without one."""
    path = with_experiment(tmp_path, attributes)
    run = experiment(read_fmu(path))
    result = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation")
    assert run.start == result["time"][0] and run.stop == result["time"][-1]
    assert run.step == pytest.approx(np.diff(result["time"]).mean(), rel=1e-9)
    assert run.tolerance is None


def test_a_tolerance_is_read(tmp_path):
    path = with_experiment(tmp_path, 'stopTime="1" tolerance="1e-5"')
    assert experiment(read_fmu(path)).tolerance == 1e-5


def test_an_experiment_that_starts_later_is_compared_from_its_start(tmp_path):
    """Dahlquist from t = 20 s (the case of an exporter whose default experiment starts late):
    both runs start there, every point is shared, and the results are bit-equal."""
    path = with_experiment(tmp_path, 'startTime="20" stopTime="21" stepSize="0.01"')
    comparison = compare_fmu(path)
    assert comparison.experiment.start == 20.0 and comparison.points == 101
    assert comparison.verdict().startswith("bit-equal")


def test_a_difference_is_measured(monkeypatch, capsys):
    """FMPy's x off by 3e-7 at one point: its size, absolute and relative to max |x| = 1."""
    simulate = fmpy.simulate_fmu

    def off(*args, **kwargs):
        result = simulate(*args, **kwargs)
        result["x"][5] += 3e-7
        return result

    monkeypatch.setattr(compare.fmpy, "simulate_fmu", off)
    path = REFERENCE_FMUS / "fmi2" / "Dahlquist.fmu"
    comparison = compare_fmu(path)
    [x] = comparison.outputs
    assert x.absolute == pytest.approx(3e-7, rel=1e-6) and x.relative == pytest.approx(3e-7,
                                                                                     rel=1e-6)
    assert not comparison.agrees() and comparison.agrees(rtol=1e-6)
    assert comparison.verdict() == "DIFFERENT: x differs by 3e-07 (relative)"
    assert comparison.verdict(1e-6) == "equal within 3e-07 (relative, x)"
    assert main(["fmu", "compare", str(path)]) == 1
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: 0 .. 10 s, step 0.1 s, tolerance none given; 101 "
                          f"common points\n")
    assert re.search(r"\n  x +3e-07 +3e-07\n  -> DIFFERENT: x differs by 3e-07", out), out
    assert main(["fmu", "compare", "--rtol", "1e-6", str(path)]) == 0


def test_differences_of_samples():
    nan = math.nan
    assert difference("a", np.array([1.0, nan]), np.array([1.0, nan])) == \
        compare.OutputDifference("a", 0.0, 0.0)
    assert difference("a", np.array([2.0, -4.0]), np.array([2.0, -3.0])).relative == 0.25
    assert difference("a", np.array([1.0, nan]), np.array([1.0, 2.0])).relative == math.inf
    assert difference("a", np.array([0.0, 1e-300]), np.array([0.0, 0.0])).relative == 1.0


def test_the_cli_exit_codes(tmp_path, capsys):
    """0 all agree, 2 a missing path or an FMU flexff cannot run (the others still run)."""
    good = [str(p) for p in REFERENCES[:2]]
    assert main(["fmu", "compare", *good]) == 0
    out = capsys.readouterr().out
    assert out.count("-> bit-equal") == 2
    junk = tmp_path / "junk.fmu"
    junk.write_text("not a zip")
    assert main(["fmu", "compare", str(tmp_path / "missing.fmu"), str(junk), *good]) == 2
    captured = capsys.readouterr()
    assert captured.out.count("-> bit-equal") == 2
    assert "missing.fmu: no such FMU file" in captured.err and "not an FMU" in captured.err
    assert main(["fmu", "compare", "--rtol", "0", *good]) == 2
