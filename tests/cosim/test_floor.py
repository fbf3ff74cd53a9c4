"""The C floor's plan (cosim/c/cosim_loop.c) is checked before anything runs: a count that is
not a number, a bus index past the bus or an output block that does not fit is an error that
names it, never a read out of bounds."""

import subprocess

import pytest

from flexff.cosim.floor import loop_program

HEADER = "flexff-cosim-plan 1\n0.001 3 1 10 1\n"
SLAVE = "/nonexistent/fmu.so\n{guid}\nplant\n0\n"  # never loaded: the plan fails first


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    """The C loop, compiled into the session's cache, not the user's."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FLEXFF_CACHE", str(tmp_path_factory.getbasetemp() / "flexff-cache"))
        return loop_program()


@pytest.mark.parametrize("plan, message", [
    (HEADER + SLAVE + "1\n7 5\n", "plant: input 0 reads bus index 5, the bus has 3 signals"),
    (HEADER + SLAVE + "0\n2 2\n", "plant: outputs at bus index 2 .. 2 + 2, the bus has 3"),
    (HEADER + SLAVE + "x\n", "plan: input count: expected a whole number, got 'x'"),
    (HEADER + SLAVE + "-1\n", "plan: input count: expected a whole number, got '-1'"),
    ("flexff-cosim-plan 1\n0.001 3 4 10 0\n", "no more sources than bus signals"),
    ("flexff-cosim-plan 1\n0.001 3 1 0 0\n", "at least one step"),
], ids=["input index", "output block", "count", "negative count", "sources", "steps"])
def test_a_plan_that_does_not_fit_is_refused(program, tmp_path, plan, message):
    (tmp_path / "plan.txt").write_text(plan)
    (tmp_path / "sources.bin").write_bytes(bytes(8 * 11 * 4))
    result = subprocess.run([str(program), str(tmp_path / "plan.txt"),
                             str(tmp_path / "sources.bin"), str(tmp_path / "record.bin"), "1"],
                            capture_output=True, text=True)
    assert result.returncode == 1 and message in result.stderr, result.stderr
