"""`flexff identify -o DIR`: DIR is a folder, as its help says and as every command's output
folder is (cosim.run.output_folder): made where missing, written into where it exists, and a
file in its place refused before any work."""

import json

import pytest

from flexff.cli import main
from flexff.learning.machine_dataset import write_machine_dataset
from tests.learning.test_description_data import machine, trajectory

pytestmark = pytest.mark.learn


@pytest.fixture
def data(tmp_path):
    one = machine(("x",))
    logs = [trajectory(("x",), k, "train") for k in range(2)] + [trajectory(("x",), 5, "test")]
    return write_machine_dataset(tmp_path / "data", one, {t.name: t.signals for t in logs},
                                 1000.0, {t.name: t.split for t in logs}, "logs").path


def test_the_output_is_a_folder_made_or_reused(tmp_path, data, capsys):
    out = tmp_path / "new" / "identified"
    assert main(["identify", str(data), "-o", str(out)]) == 0
    written = json.loads((out / "identified.json").read_text())
    assert written["axes"]["x"]["terms"][0] == "inertia"
    assert main(["identify", str(data), "-o", str(out)]) == 0  # an existing folder: fine
    assert f"wrote {out / 'identified.json'}" in capsys.readouterr().out


def test_a_file_in_the_folder_s_place_is_refused_before_any_work(tmp_path, data, capsys):
    (tmp_path / "taken").write_text("mine")
    assert main(["identify", str(data), "-o", str(tmp_path / "taken")]) == 2
    captured = capsys.readouterr()
    assert "taken" in captured.err and "not a folder" in captured.err
    assert captured.out == ""  # no identification ran
    assert (tmp_path / "taken").read_text() == "mine"
