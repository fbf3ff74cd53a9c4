"""README "Your own network", run word for word: the Python and shell blocks under the
`<!-- own-network.py -->` and `<!-- own-network.sh -->` markers, in an empty folder; the FMU then
gives what onnxruntime gives for the exported graph."""

import os
import re
import subprocess
import sys

import numpy as np
import onnxruntime as ort

from tests.helpers import REPOSITORY
from tests.runners import run_fmu


def readme_block(marker: str) -> str:
    """The fenced code block right after `<!-- marker -->` in the README."""
    text = (REPOSITORY / "README.md").read_text()
    found = re.search(rf"<!-- {re.escape(marker)} -->\n```\w+\n(.*?)```", text, re.DOTALL)
    assert found, f"README.md has no code block after <!-- {marker} -->"
    return found.group(1)


def test_readme_own_network_snippet_runs_as_written(tmp_path):
    (tmp_path / "own-network.py").write_text(readme_block("own-network.py"))
    environment = {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}"}
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", readme_block("own-network.sh")],
                          cwd=tmp_path, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "own.fmu: OK" in done.stdout
    u = np.array([[0.3, -0.2]], dtype=np.float32)
    expected = ort.InferenceSession(str(tmp_path / "own.onnx")).run(None, {"u": u})[0].item()
    out = run_fmu(tmp_path / "own.fmu", 20, inputs={"u[0]": 0.3, "u[1]": -0.2}, record=["y"])
    assert out["y"][-1] == np.float32(expected)  # the graph's own float32 result, held
