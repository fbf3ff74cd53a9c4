"""A machine loop's noise floor (`[machine] exact`): what the measurement alone adds to e2,
measured as the manipulator's is, and refused with the key where the loop lacks the FMU."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flexff.cosim.config import load_config
from flexff.cosim.config_error import ConfigError
from flexff.learning.ilc_loops import MachineLoop, identified_on_trial
from flexff.learning.machine_loop import with_feedforward, with_start_values

EXAMPLE = Path(__file__).parents[2] / "flexff" / "machines" / "examples" / "drive.toml"


def drive_loop(**machine_changes):
    loop = load_config(EXAMPLE)
    return replace(loop, stop=3.0, machine=replace(loop.machine, **machine_changes))


def zero_table(folder: Path) -> Path:
    table = folder / "zero.csv"
    np.savetxt(table, np.column_stack([np.arange(3001) * 1e-3, np.zeros(3001)]),
               delimiter=",", header="time,x_ff", comments="")
    return table


def test_the_floor_is_what_the_encoder_adds_to_e2(tmp_path):
    loop = MachineLoop(drive_loop(), identified_on_trial)
    table = zero_table(tmp_path)
    floor = loop.noise_floor(table)["x"]
    noisy = loop.metrics(loop._run(with_feedforward(loop.config, table))[0])["x"]["e2"]
    exact = with_start_values(loop.config, loop.machine.exact, "machine.exact")
    clean = loop.metrics(loop._run(with_feedforward(exact, table))[0])["x"]["e2"]
    assert 0 < floor < noisy
    # the encoder's error and the loop's own are uncorrelated: their squares add
    assert np.hypot(clean, floor) == pytest.approx(noisy, rel=0.1)


def test_without_exact_start_values_the_floor_is_unknown(tmp_path):
    assert MachineLoop(drive_loop(exact={}), identified_on_trial).noise_floor(
        zero_table(tmp_path)) is None


def test_an_instance_the_loop_lacks_is_refused_naming_the_key(tmp_path):
    loop = MachineLoop(drive_loop(exact={"plant.encoder": 0.0}), identified_on_trial)
    with pytest.raises(ConfigError, match=r"machine\.exact\.plant\.encoder: the loop has no "
                                          r"FMU 'plant'"):
        loop.noise_floor(zero_table(tmp_path))
