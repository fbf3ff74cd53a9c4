"""The tutorials run as written: in each, every block after `<!-- save: FILE -->` is saved as
FILE and every block after `<!-- run -->` runs in bash, in page order, in an empty folder."""

import os
import re
import subprocess
import sys

import pytest

from tests.helpers import REPOSITORY

STEP = re.compile(r"<!-- (run|save: (\S+)) -->\n```\w*\n(.*?)```", re.DOTALL)
TUTORIALS = ["first-cosimulation", "thesis-feedforward",
             pytest.param("own-machine", marks=pytest.mark.learn), "real-time"]


def steps(page: str) -> list[tuple[str | None, str]]:
    """(None, commands) or (file name, text) for each marked block of `page`, in order."""
    text = (REPOSITORY / "docs" / "tutorials" / f"{page}.md").read_text()
    return [(m[2], m[3]) for m in STEP.finditer(text)]


@pytest.mark.parametrize("page", TUTORIALS)
def test_tutorial_runs_as_written(page, tmp_path):
    environment = {**os.environ, "PYTHONPATH": str(REPOSITORY),  # this checkout's flexff
                   "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}"}
    assert steps(page), page
    for name, text in steps(page):
        if name is not None:
            (tmp_path / name).write_text(text)
            continue
        done = subprocess.run(["bash", "-euo", "pipefail", "-c", text], cwd=tmp_path,
                              env=environment, capture_output=True, text=True)
        assert done.returncode == 0, f"{text}\n{done.stdout}{done.stderr}"
