"""The rough drive example (flexff/machines/examples/drive-rough.toml): the drive with effects its
description's default prior does not hold, so that its identified model leaves what a learned
model may add; the drive example's prior holds its plant whole."""

from pathlib import Path

import pytest

from flexff.cosim.run import load_run_config
from flexff.learning.machine_collect import collect_machine
from flexff.learning.machine_identify import identify_dataset

EXAMPLES = Path(__file__).parents[2] / "flexff" / "machines" / "examples"


def _identified_error(name: str, folder: Path) -> float:
    loop = load_run_config(EXAMPLES / f"{name}.toml")
    data = collect_machine(loop, folder, 3, 1, 6.0, workers=1, progress=False)
    return identify_dataset(data).axes["x"].relative_error


@pytest.mark.slow
def test_the_rough_drives_prior_leaves_its_effects_out(tmp_path):
    drive, rough = (_identified_error(n, tmp_path / n) for n in ("drive", "drive-rough"))
    assert drive < 0.01  # cogging's shape in the prior: the plant whole
    assert rough > 5 * drive


def test_the_rough_drive_is_the_drive_with_its_effects_on():
    rough = load_run_config(EXAMPLES / "drive-rough.toml")
    drive = load_run_config(EXAMPLES / "drive.toml")
    (plant,) = (f for f in rough.fmus if f.name == "drive")
    assert plant.builtin == "drive" and plant.parameters["current_lag"] > 0
    assert {k for k, v in plant.parameters.items() if v} == {
        "stribeck", "stribeck_velocity", "friction_ripple", "friction_period", "force_ripple",
        "ripple_pitch", "spring", "spring_cubic", "current_lag"}
    assert rough.machine is not None and drive.machine is not None
    assert rough.machine.prior.terms == ("inertia", "viscous", "coulomb", "offset")
    assert not rough.machine.prior.extra and drive.machine.prior.extra  # no cogging term
    assert rough.machine.axes == drive.machine.axes
