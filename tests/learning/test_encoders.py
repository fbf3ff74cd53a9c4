"""A loop with counted or noisy encoders given preprocessing made for ideal ones is warned of
(learning.encoders): by flexff evaluate --env sim --config, its --data, and flexff data
collect --set sim --config; the nominal loop and the hardware settings are not."""

import warnings

import pytest

import flexff.learning.collect
import flexff.learning.evaluate
from flexff.cli import main
from flexff.cosim.config import parse_config
from flexff.fmu.build import build_fmu
from flexff.learning.collect import run_collection
from flexff.learning.dataset import load_dataset, write_dataset
from flexff.learning.encoders import EncoderWarning, loop_encoders, warn_ideal_preprocessing
from flexff.learning.evaluate import evaluate, preprocessing
from flexff.learning.loop import default_loop
from flexff.learning.synthetic import synthetic_dataset
from flexff.plant.system import plant_system


def loop(**plant):
    return parse_config({"reference": {"kind": "thesis-eval"}, "plant": plant}, name="loop",
                        origin="loop.toml")


def test_the_plant_says_whether_its_encoders_are_ideal(tmp_path):
    assert loop_encoders(default_loop("nominal")) == {}
    assert loop_encoders(default_loop("hardware")) == {"encoder_quantization": 1.0,
                                                       "noise_std": 1e-3}
    assert loop_encoders(loop(noise_std=2e-4)) == {"noise_std": 2e-4}
    assert loop_encoders(loop(variant="hardware", encoder_quantization=0, noise_std=0)) == {}
    fmu = build_fmu(plant_system("hardware"), tmp_path / "machine.fmu")
    by_path = parse_config({"reference": {"kind": "thesis-eval"}, "fmu": {
        "controller": {"builtin": "controller"},
        "machine": {"path": str(fmu), "parameters": {"noise_std": 0.0}}}})
    assert loop_encoders(by_path) == {"encoder_quantization": 1.0}


def test_only_ideal_preprocessing_on_a_noisy_loop_is_warned_of():
    noisy = loop_encoders(default_loop("hardware"))
    with pytest.warns(EncoderWarning, match=r"the loop x has encoders that count or are noisy "
                                            r"\(encoder_quantization = 1, noise_std = 0.001\)"
                                            r".*a 5 Hz low-pass.*--env hardware"):
        warn_ideal_preprocessing(preprocessing("sim")[0], noisy, "the loop x")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert warn_ideal_preprocessing(preprocessing("hardware")[0], noisy, "x") is None
        assert warn_ideal_preprocessing(preprocessing("sim")[0], {}, "x") is None


class Stop(Exception):
    """Raised where the evaluation would start collecting."""


def stop(*args, **kwargs):
    raise Stop


def test_evaluate_warns_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setattr(flexff.learning.evaluate, "collect", stop)
    with pytest.warns(EncoderWarning, match="the loop noisy.toml has encoders"):
        with pytest.raises(Stop):
            evaluate("sim", tmp_path, loop=parse_config(
                {"reference": {"kind": "thesis-eval"}, "plant": {"variant": "hardware"}},
                origin="noisy.toml"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for env, variant in (("sim", "nominal"), ("hardware", "hardware")):
            with pytest.raises(Stop):
                evaluate(env, tmp_path, loop=default_loop(variant))


def test_evaluate_warns_of_a_noisy_dataset(tmp_path, monkeypatch):
    ideal = load_dataset(synthetic_dataset(tmp_path / "ideal", n_train=1, n_test=1,
                                           duration=2.0))
    noisy = write_dataset(tmp_path / "noisy", "sim", ideal.sample_rate_hz, {
        "variant": "nominal", "parameters": {**ideal.plant["parameters"], "noise_std": 1e-3}},
        list(ideal.trajectories))
    monkeypatch.setattr(flexff.learning.evaluate, "train_parallel", stop)
    with pytest.warns(EncoderWarning, match=f"the dataset {noisy} has encoders"):
        with pytest.raises(Stop):
            evaluate("sim", tmp_path, data=noisy, models=["pgnn"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(Stop):
            evaluate("sim", tmp_path, data=ideal.path, models=["pgnn"])


def test_collecting_the_sim_set_on_a_noisy_loop_is_warned_of(tmp_path, capsys, monkeypatch):
    with pytest.warns(EncoderWarning, match="the sim set is made for the nominal plant's ideal "
                                            "encoders.*noisy.toml has encoders"):
        run_collection("sim", tmp_path / "noisy", progress=False, limit=1,
                       config=parse_config({"reference": {"kind": "thesis-eval"},
                                            "plant": {"noise_std": 1e-3}}, origin="noisy.toml"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run_collection("sim", tmp_path / "nominal", progress=False, limit=1,
                       config=loop(m_up1=0.12))
    config = tmp_path / "noisy.toml"
    config.write_text('[reference]\nkind = "thesis-eval"\n[plant]\nvariant = "hardware"\n')

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt  # the warning is out before the first trajectory runs

    monkeypatch.setattr(flexff.learning.collect, "_execute", interrupted)
    assert main(["data", "collect", "--set", "sim", "--config", str(config), "-o",
                 str(tmp_path / "cli")]) == 130
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"flexff: warning: the sim set is made for the nominal plant's "
                             f"ideal encoders, and flexff evaluate --env sim preprocesses it "
                             f"for them, but {config} has encoders")
    assert err[1].startswith("flexff: interrupted")
