"""The how-to "Bring your own network", run word for word: the Python and shell blocks under the
`<!-- own-network.py -->` and `<!-- own-network.sh -->` markers, in an empty folder; the FMU then
gives what onnxruntime gives for the exported graph (its C network to float32 rounding)."""

import numpy as np
import onnxruntime as ort
import pytest

from tests.helpers import NETWORK_RTOL, run_readme_snippet
from tests.runners import run_fmu

pytestmark = pytest.mark.learn  # the how-to exports its network with PyTorch


def test_readme_own_network_snippet_runs_as_written(tmp_path):
    assert "own.fmu: OK" in run_readme_snippet(tmp_path, "own-network")
    u = np.array([[0.3, -0.2]], dtype=np.float32)
    expected = ort.InferenceSession(str(tmp_path / "own.onnx")).run(None, {"u": u})[0].item()
    out = run_fmu(tmp_path / "own.fmu", 20, inputs={"u[0]": 0.3, "u[1]": -0.2}, record=["y"])
    assert out["y"][-1] == pytest.approx(expected, rel=NETWORK_RTOL, abs=1e-6)  # held
