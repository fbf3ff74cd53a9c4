"""Run configurations: the examples, and every kind of mistake caught before simulating with a
message naming table.key."""

import json

import pytest

from flexff.controllers.feedback import parasitic_mode_hz
from flexff.controllers.manipulator import controller_for
from flexff.cosim.config import ConfigError, config_examples, load_config, parse_config
from flexff.cosim.run import run_config
from flexff.plant.references import thesis_evaluation

GOOD = """
[run]
step = 0.001
stop = 2.0

[reference]
kind = "circle"
radius = 0.01
duration = 2.0
"""


def write(folder, text, name="run.toml"):
    path = folder / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", sorted(config_examples()))
def test_examples_are_valid(name):
    config = parse_config(config_examples()[name], name=name)
    assert config.name == name and config.steps * config.step == pytest.approx(config.stop)


def test_defaults_and_resolution(tmp_path):
    config = load_config(write(tmp_path, GOOD))
    assert config.name == "run" and config.steps == 2000
    plant, controller = config.builtin("plant"), config.builtin("controller")
    assert [f.name for f in config.fmus] == ["controller", "plant"]  # no feedforward FMU
    assert config.sources[0].values == {"Fx_ff": 0.0, "Fy_ff": 0.0}  # ... but zero forces
    assert plant.options == {"variant": "nominal"} and controller.options["encoders"] == 2
    assert controller.options["variant"] == "nominal" and config.record.signals is None
    # the plant starts at rest where the reference starts
    assert plant.parameters == {"x_start": 0.01, "y_start": 0.0}
    thesis = parse_config('[reference]\nkind = "thesis-eval"\n')
    assert thesis.stop == pytest.approx(thesis_evaluation().duration)


def test_csv_paths_are_relative_to_the_configuration(tmp_path):
    folder = tmp_path / "configs"
    folder.mkdir()
    thesis_evaluation(1e-3).to_csv(folder / "ref.csv")
    config = load_config(write(folder, '[reference]\nkind = "csv"\npath = "ref.csv"\n'))
    assert config.reference.options["path"] == (folder / "ref.csv").resolve()
    assert config.stop == pytest.approx(15.0)


@pytest.mark.parametrize("change, key, message", [
    ({"run": "stop = 2.0\nsteps = 3"}, "run.steps", "unknown key"),
    ({"extra": "a = 1"}, "extra", "unknown table"),
    ({"plant": 'variant = "nominal"\nmass = 3.0'}, "plant.mass", "unknown key"),
    ({"run": "step = 0.003\nstop = 2.0"}, "run.stop", "not a whole number of steps"),
    ({"plant": 'variant = "prototype"'}, "plant.variant", "unknown variant 'prototype'"),
    ({"run": 'step = "1 ms"'}, "run.step", "expected a number"),
    ({"run": "stop = true"}, "run.stop", "expected a number"),
    ({"run": "step = -0.001"}, "run.step", "must be positive"),
    ({"controller": "encoders = 4"}, "controller.encoders", "must be one of (2, 3)"),
    ({"controller": 'notch = "yes"'}, "controller.notch", "expected a number"),
    ({"plant": "seed = 1.5"}, "plant.seed", "expected an integer"),
    ({"plant": "k_t1 = -0.03"}, "plant.k_t1", "must be positive"),
    ({"plant": "x_start = 0.2"}, "plant.x_start", "outside the workspace"),
    ({"feedforward": 'kind = "lstm"'}, "feedforward.kind", "unknown kind 'lstm'"),
    ({"feedforward": 'kind = "rigid-body"\nmodel = "a.onnx"'}, "feedforward.model", "unknown key"),
    ({"record": "signals = 3"}, "record.signals", "expected a list"),
])
def test_mistakes_name_the_key(tmp_path, change, key, message):
    tables = {"run": "stop = 2.0", "reference": 'kind = "circle"\nradius = 0.01\nduration = 2.0'}
    tables.update(change)
    text = "\n".join(f"[{name}]\n{body}\n" for name, body in tables.items())
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, text))
    assert f": {key}: " in str(info.value) and message in str(info.value)
    assert str(tmp_path / "run.toml") in str(info.value)


@pytest.mark.parametrize("reference, key, message", [
    ('kind = "csv"\npath = "missing.csv"', "reference.path", "no such file"),
    ('kind = "circle"\nradius = 0.04\ncentre = [0.02, 0.0]\nduration = 2.0',
     "reference.radius, reference.centre, reference.duration", "outside the workspace"),
    ('kind = "spline"\npoints = [[0, 0], [0.01, 0.06], [0.02, 0]]\nduration = 3.0',
     "reference.points, reference.duration", "outside the workspace"),
    ('kind = "circle"\nduration = 2.0', "reference.radius", "required"),
    ('kind = "line"', "reference.kind", "unknown kind 'line'"),
    ('radius = 0.01', "reference.kind", "required"),
])
def test_reference_mistakes(tmp_path, reference, key, message):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, f"[reference]\n{reference}\n"))
    assert f": {key}" in str(info.value) and message in str(info.value)


def test_a_reference_outside_the_workspace_in_a_csv_file(tmp_path):
    (tmp_path / "far.csv").write_text("t,x_ref,y_ref\n0,0,0\n1,0.03,0.03\n2,0.06,0\n")
    with pytest.raises(ConfigError, match=r"reference.path.*outside the workspace"):
        load_config(write(tmp_path, '[reference]\nkind = "csv"\npath = "far.csv"\n'))


def test_the_old_name_of_the_rigid_body_feedforward_still_reads(tmp_path):
    new = load_config(write(tmp_path, GOOD + '[feedforward]\nkind = "rigid-body"\n'))
    with pytest.warns(FutureWarning, match="kind = 'model' is deprecated, write kind = 'rig"):
        old = load_config(write(tmp_path, GOOD + '[feedforward]\nkind = "model"\n'))
    assert old.fmus == new.fmus


def test_onnx_feedforward_model_is_checked(tmp_path):
    text = GOOD + '[feedforward]\nkind = "learned"\nmodel = "ff.onnx"\n'
    with pytest.raises(ConfigError, match=r"feedforward.model: no such file"):
        load_config(write(tmp_path, text))
    (tmp_path / "ff.onnx").write_bytes(b"")
    with pytest.raises(ConfigError, match=r"feedforward.model: .*not a flexff feedforward model"):
        load_config(write(tmp_path, text))


def test_bad_configuration_fails_before_anything_is_written(tmp_path):
    path = write(tmp_path, GOOD.replace("stop = 2.0", "stop = 2.0005"))
    with pytest.raises(ConfigError, match=r"run.stop"):
        run_config(path, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_unknown_record_signal_fails_before_the_run(tmp_path):
    path = write(tmp_path, GOOD + '[record]\nsignals = ["x", "z"]\n')
    with pytest.raises(ConfigError, match=r"record.signals: cannot record unknown signal 'z'"):
        run_config(path, tmp_path / "out")
    assert not (tmp_path / "out" / "signals.parquet").exists()


def test_not_toml(tmp_path):
    with pytest.raises(ConfigError, match="file: not valid TOML"):
        load_config(write(tmp_path, "[run\nstep = 1"))
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_config(tmp_path / "nothing.toml")


@pytest.mark.parametrize("variant, controller, crossover, notch", [
    ("nominal", "", 2.66, False),
    ("hardware", "", 2.0, True),
    ("hardware", "notch = false", 2.0, False),
    ("nominal", "notch = true\ncrossover_hz = 3.0", 3.0, True),
    ("nominal", "notch = 25.0", 2.66, 25.0),
])
def test_controller_follows_the_configuration(variant, controller, crossover, notch):
    config = parse_config(f'[reference]\nkind = "thesis-eval"\n[plant]\nvariant = "{variant}"\n'
                          f'[controller]\n{controller}\nencoders = 3\n')
    design = json.loads(controller_for(config.builtin("controller").options,
                                       config.step).extra["design"])
    assert design["requested_crossover_hz"] == pytest.approx(crossover)
    expected = parasitic_mode_hz() if notch is True else (notch or 0.0)
    assert design["notch_hz"] == pytest.approx(expected) and design["encoders"] == 3
