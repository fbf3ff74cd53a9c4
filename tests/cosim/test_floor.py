"""The C floor's plan (cosim/c/floor.c) is checked before the loop runs: its form by the
program (a count that is not a number, no step), whether it fits by the engine compiled into
it (a bus index past the bus, an output block or the sources outside it); each is an error that
names it, never a read out of bounds."""

import subprocess
import zipfile

import fmpy
import pytest

from flexff.cosim.floor import loop_program
from tests.helpers import REFERENCE_FMUS

FEEDTHROUGH = REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"
HEADER = "flexff-cosim-plan 1\n0.001 3 1 10 1\n"
UNREAD = "/nonexistent/fmu.so\n{guid}\nplant\n"  # never loaded: the plan's form fails first


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    """The floor, compiled into the session's cache, not the user's."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))
        return loop_program()


@pytest.fixture(scope="module")
def feedthrough(tmp_path_factory):
    """A plan's FMU lines for Feedthrough, which the floor loads and instantiates before the
    engine checks the plan."""
    folder = tmp_path_factory.mktemp("feedthrough")
    with zipfile.ZipFile(FEEDTHROUGH) as zf:
        zf.extractall(folder)
    library = folder / "binaries" / fmpy.platform / f"Feedthrough{fmpy.sharedLibraryExtension}"
    return f"{library}\n{fmpy.read_model_description(str(FEEDTHROUGH)).guid}\nft\n0\n"


def refusal(program, folder, plan, repeats="1"):
    """The floor's exit code and message on `plan` with 10 steps of sources."""
    (folder / "plan.txt").write_text(plan)
    (folder / "sources.bin").write_bytes(bytes(8 * 11 * 4))
    result = subprocess.run([str(program), str(folder / "plan.txt"), str(folder / "sources.bin"),
                             str(folder / "record.bin"), repeats], capture_output=True, text=True)
    return result.returncode, result.stderr


@pytest.mark.parametrize("repeats, message", [
    ("0", "REPEATS must be at least 1"), ("ten", "REPEATS: expected a whole number, got 'ten'"),
])
def test_bad_repeats_are_refused(program, tmp_path, repeats, message):
    code, stderr = refusal(program, tmp_path, HEADER + UNREAD, repeats)
    assert code == 1 and message in stderr, stderr


@pytest.mark.parametrize("plan, message", [
    (HEADER + UNREAD + "0\nx\n", "plan: input count: expected a whole number, got 'x'"),
    (HEADER + UNREAD + "0\n-1\n", "plan: input count: expected a whole number, got '-1'"),
    (HEADER + UNREAD + "0\n0\n-2 0\n", "plan: bad output header '-2 0'"),
    (HEADER + UNREAD + "0\n1\n-7 0\n", "plan: bad input line '-7 0'"),
    (HEADER + UNREAD + "1\n7 X 1.0\n", "plan: bad parameter line '7 X 1.0'"),
    ("flexff-cosim-plan 1\n0.001 3 1 0 0\n", "at least one step"),
], ids=["count", "negative count", "negative output count", "value reference", "parameter",
        "steps"])
def test_a_plan_of_the_wrong_form_is_refused(program, tmp_path, plan, message):
    code, stderr = refusal(program, tmp_path, plan)
    assert code == 1 and message in stderr, stderr


@pytest.mark.parametrize("fmu, message", [
    ("1\n7 5\n0 2\n0 1\n", "plan: fmu 0: input 0 reads bus index 5"),
    ("0\n2 2\n10\n11\n0 1\n", "plan: fmu 0: its 2 outputs do not lie inside the bus of 3"),
    ("0\n1 9\n10\n0 1\n", "plan: fmu 0: its 1 outputs do not lie inside the bus of 3"),
], ids=["input index", "output block", "output offset"])
def test_a_plan_that_does_not_fit_is_refused_by_the_engine(program, feedthrough, tmp_path,
                                                          fmu, message):
    code, stderr = refusal(program, tmp_path, HEADER + feedthrough + fmu)
    assert code == 1 and message in stderr, stderr


def test_sources_outside_the_bus_are_refused_by_the_engine(program, tmp_path):
    code, stderr = refusal(program, tmp_path, "flexff-cosim-plan 1\n0.001 3 4 10 0\n")
    assert code == 1 and "plan: 0 FMUs, 4 sources or 3 columns do not fit the bus" in stderr
