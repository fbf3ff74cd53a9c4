"""`flexff fmu info`: what an FMU declares, read from its model description and archive."""

import json

import pytest

from flexff.cli import main
from flexff.fmu.info import fmu_summary
from tests.array_plant import build_array_plant
from tests.helpers import REFERENCE_FMUS


@pytest.mark.parametrize("version, platform", [("2", "linux64"), ("3", "x86_64-linux")])
def test_a_reference_fmu_s_ports_dependencies_and_experiment(version, platform):
    summary = fmu_summary(REFERENCE_FMUS / f"fmi{version}" / "Feedthrough.fmu")
    assert summary["fmi_version"] == f"{version}.0"
    assert summary["interfaces"]["co-simulation"] == "Feedthrough"
    assert platform in summary["platforms"] and summary["sources"]
    assert summary["default_experiment"]["stop"] == 2.0
    first = summary["variables"][0]  # inputs first, by value reference
    assert first["causality"] == "input" and first["start"] == 0.0
    assert first["type"] in ("Real", "Float32")
    assert all(d["declared"] for d in summary["dependencies"].values())
    json.dumps(summary)  # plain data


def test_undeclared_dependencies_are_told_with_the_setting(tmp_path, capsys):
    plant = build_array_plant(tmp_path)
    summary = fmu_summary(plant)
    assert summary["dependencies"]["pos[1]"] == {
        "declared": False, "state": False, "inputs": ["force[1]", "force[2]", "force[3]"]}
    assert main(["fmu", "info", str(plant)]) == 0
    text = capsys.readouterr().out
    assert "pos[1]: not declared, so by FMI every input" in text
    assert "feedthrough = false" in text
    assert "'tip speed'  output      Real        m/s" in text
    assert "local variables: --all lists them" in text
    assert main(["fmu", "info", "--all", "--json", str(plant)]) == 0
    listed = json.loads(capsys.readouterr().out)["variables"]
    assert {"q1", "v3"} <= {v["name"] for v in listed}


def test_a_missing_file_is_a_one_line_error(tmp_path, capsys):
    assert main(["fmu", "info", str(tmp_path / "none.fmu")]) == 2
    assert "none.fmu: no such FMU file" in capsys.readouterr().err
