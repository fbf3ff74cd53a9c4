"""Non-finite values: a NaN or infinite output stops a run (in-process or isolated) with exit
code 1 and one line naming the FMU, the output and the time, the record kept up to the point
before; a NaN, an infinity or a Float32 overflow among the parameters is refused when the
configuration is read, naming its key; `allow_nonfinite` lets them through where meant."""

import json

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim.config import expanded, parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.recording import load_recording
from tests.helpers import REFERENCE_FMUS

VDP = REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"  # mu = 1e6 sends x1 to -inf at t = 0.09 s
FEEDTHROUGH3 = REFERENCE_FMUS / "fmi3" / "Feedthrough.fmu"


def blowing_up(tmp_path, fmu_keys=""):
    path = tmp_path / "run.toml"
    path.write_text(f'[run]\nstep = 0.01\nstop = 1.0\n[fmu.vdp]\npath = "{VDP}"\n'
                    f'parameters = {{ mu = 1e6 }}\n{fmu_keys}')
    return path


@pytest.mark.parametrize("isolate", [False, True])
def test_a_nonfinite_output_stops_the_run(tmp_path, capsys, isolate):
    out = tmp_path / "out"
    code = main(["run", str(blowing_up(tmp_path)), "-o", str(out), *["--isolate"] * isolate])
    err = capsys.readouterr().err
    assert code == 1
    assert err == ("flexff: error: vdp: output 'x1' is -inf at t = 0.09 s: a non-finite value "
                   "stops the run (set allow_nonfinite = true in [fmu.vdp], or in [run] for "
                   "every FMU, where it is meant); the record up to t = 0.08 s (9 points) is in "
                   f"{out}\n")
    kept = load_recording(out)
    assert np.allclose(kept.time, np.arange(9) * 0.01)
    assert np.all(np.isfinite(kept["vdp.x1"]))
    recorded = json.loads((out / "run.json").read_text())["recorded"]
    assert (recorded["points"], recorded["complete"]) == (9, False)


def test_allow_nonfinite_lets_a_run_go_on(tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(blowing_up(tmp_path, "allow_nonfinite = true\n")), "-o",
                 str(out)]) == 0
    assert not np.all(np.isfinite(load_recording(out)["vdp.x1"]))


@pytest.mark.parametrize("fmu, parameters, key", [
    (VDP, {"mu": float("nan")}, "fmu.f.parameters.mu"),
    (VDP, {"mu": float("-inf")}, "fmu.f.parameters.mu"),
    (FEEDTHROUGH3, {"Float32_continuous_input": 1e308},
     "fmu.f.parameters.Float32_continuous_input"),
])
def test_nonfinite_parameters_are_refused_unless_allowed(fmu, parameters, key):
    def config(run=None, allow=None):
        return parse_config({"run": {"step": 0.1, "stop": 1.0, **(run or {})},
                             "fmu": {"f": {"path": str(fmu), "parameters": parameters,
                                           "unconnected": "start", **(allow or {})}}})

    with pytest.raises(ConfigError) as refused:
        config()
    assert refused.value.key == key
    assert len(str(refused.value).splitlines()) == 1
    assert config(allow={"allow_nonfinite": True}).fmus[0].allow_nonfinite
    assert config(run={"allow_nonfinite": True}).fmus[0].allow_nonfinite


def test_run_allow_nonfinite_reaches_every_fmu_and_is_kept():
    """[run] allow_nonfinite reaches a short form's FMUs too, and survives the general form."""
    config = parse_config({"run": {"allow_nonfinite": True, "stop": 0.1},
                           "reference": {"kind": "circle", "radius": 0.01, "duration": 0.1}})
    assert config.fmus and all(f.allow_nonfinite for f in config.fmus)
    again = parse_config(expanded(config))
    assert all(f.allow_nonfinite for f in again.fmus)
