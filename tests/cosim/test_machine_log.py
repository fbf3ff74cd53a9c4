"""A machine's log map ([machine.log]): the time column, scalars and per dataset signal an
expression of the log's columns, checked when the description is read."""

import pytest

from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import LogMap, parse_machine

AXIS = {"name": "x", "measured": "plant.x", "feedforward": "pid.x_ff", "effort": "pid.x_effort",
        "range": [-0.05, 0.05], "velocity": 0.2, "acceleration": 2.0}


def drive(log=None):
    table = {"name": "drive", "axis": [AXIS]}
    return parse_machine({**table, "log": log} if log is not None else table, "drive.toml")


def test_a_map_is_read_as_data():
    log = drive({"time": "t", "scalars": {"gain": 2.5, "offset": -1},
                 "columns": {"x_measured": "enc_pos", "x_effort": "gain * vir + offset"}}).log
    assert (log.time, dict(log.scalars)) == ("t", {"gain": 2.5, "offset": -1.0})
    assert log.columns["x_effort"].names == {"gain", "vir", "offset"}
    assert set(log.columns) == {"x_measured", "x_effort"}
    assert drive().log == LogMap()  # no map: the canonical names


@pytest.mark.parametrize("log, key, words", [
    ({"columns": {"x_effort": "gain *"}}, r"machine\.log\.columns\.x_effort",
     "is not an expression"),
    ({"columns": {"x_effort": "__import__('os')"}}, r"machine\.log\.columns\.x_effort",
     "not one of"),
    ({"columns": {"x_efort": "vir"}}, r"machine\.log\.columns\.x_efort",
     "not a dataset signal of this machine \\(did you mean 'x_effort'\\?\\); its signals: x_ref"),
    ({"columns": {"time": "t"}}, r"machine\.log\.columns\.time", "machine.log.time"),
    ({"scalars": {"gain": 2.5}, "columns": {"x_effort": "gain * 2"}},
     r"machine\.log\.columns\.x_effort", "names no column of the log, only scalars"),
    ({"scalars": {"pi": 3.0}}, r"machine\.log\.scalars\.pi", "no function or constant"),
    ({"scalars": {"x_ref": 0.0}}, r"machine\.log\.scalars\.x_ref", "is a dataset signal"),
    ({"scalars": {"gain": "2.5"}}, r"machine\.log\.scalars\.gain", "finite number"),
    ({"time": ""}, r"machine\.log\.time", "non-empty string"),
    ({"rows": 3}, r"machine\.log\.rows", "unknown key"),
])
def test_a_bad_map_is_refused_naming_its_key(log, key, words):
    with pytest.raises(ConfigError, match=rf"^drive\.toml: {key}: .*{words}"):
        drive(log)


