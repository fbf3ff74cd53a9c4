"""The example loops' reference tables are what learning.excitation draws (class "moves", seed
1000, at the loop's step), as their configurations say: a table coarser than the step would
make each position disagree with its velocity between samples (linear interpolation)."""

from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.config import load_config
from flexff.learning.excitation import excitation_set
from flexff.learning.machine_loop import loop_machine

EXAMPLES = Path(__file__).parents[2] / "flexff" / "machines" / "examples"


@pytest.mark.parametrize("name", ["drive", "stage"])
def test_the_reference_table_is_the_excitation_at_the_loop_step(name: str) -> None:
    loop = load_config(EXAMPLES / f"{name}.toml")
    table = np.loadtxt(EXAMPLES / f"{name}-reference.csv", delimiter=",", skiprows=1)
    header = (EXAMPLES / f"{name}-reference.csv").read_text().splitlines()[0].split(",")
    assert np.allclose(np.diff(table[:, 0]), loop.step)
    drawn = excitation_set(loop_machine(loop), 1, 1, table[-1, 0], 1 / loop.step, seed=1000,
                           classes=("moves",), synchronised=True)[1]
    for k, signal in enumerate(header[1:], start=1):
        assert np.allclose(table[:, k], drawn.signals[signal], rtol=1e-9, atol=1e-12), signal
