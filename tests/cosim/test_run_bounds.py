"""Sizes a run takes from its configuration are bounded before anything is spent: a run.stop
of 1e300 (more steps than a run can count) is one line naming run.stop when the configuration
is read, and a record larger than the free disk is refused naming run.stop and run.step
before the run writes a byte."""

import pytest

from flexff.cli import main
from flexff.cosim.config import parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.run import run_config
from tests.cosim.test_streaming import VDP, vdp_config


@pytest.mark.parametrize("stop", ["1e300", "1.7e308"])
def test_an_endless_stop_names_its_key(tmp_path, capsys, stop):
    (tmp_path / "run.toml").write_text(vdp_config(stop))
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"flexff: error: {tmp_path / 'run.toml'}: run.stop: the run's length ")
    assert err.endswith("steps of 0.001 s, more than the 9.01e+15 a run can count: shorten "
                        "run.stop or enlarge run.step\n") and len(err.splitlines()) == 1


def test_a_record_larger_than_the_free_disk_is_refused_before_it_is_written(tmp_path):
    config = parse_config({"run": {"step": 1e-6, "stop": 1e9},  # 1e15 points: petabytes
                           "fmu": {"vdp": {"path": str(VDP)}}}, origin="big.toml")
    with pytest.raises(ConfigError, match=r"^big.toml: run.stop, run.step: the record of "
                                          r"1e\+15 points x 3 columns needs .* GB, more than "
                                          r"the .* GB free in .*: shorten run.stop, enlarge "
                                          r"run.step, record fewer signals"):
        run_config(config, tmp_path / "out")
    assert list((tmp_path / "out").iterdir()) == []
