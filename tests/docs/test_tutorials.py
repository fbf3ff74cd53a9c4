"""The tutorials run as written: in each, every block after `<!-- save: FILE -->` is saved as
FILE and every block after `<!-- run -->` runs in bash, in page order, in an empty folder. Each
`<!-- figure: MADE -->` stands over the image the page shows: the plot MADE that the steps
write, the same size. FLEXFF_TUTORIAL_FIGURES=1 copies the plots made into the page's images
(then look at them and commit them)."""

import os
import re
import subprocess
import sys

import pytest
from PIL import Image

from tests.helpers import REPOSITORY

STEP = re.compile(r"<!-- (run|save: (\S+)) -->\n```\w*\n(.*?)```", re.DOTALL)
FIGURE = re.compile(r"<!-- figure: (\S+) -->\n!\[[^\]]+\]\((\S+)\)")
TUTORIALS = ["first-cosimulation", "thesis-feedforward",
             pytest.param("own-machine", marks=pytest.mark.learn), "real-time"]


def text(page: str) -> str:
    return (REPOSITORY / "docs" / "tutorials" / f"{page}.md").read_text()


def steps(page: str) -> list[tuple[str | None, str]]:
    """(None, commands) or (file name, text) for each marked block of `page`, in order."""
    return [(m[2], m[3]) for m in STEP.finditer(text(page))]


@pytest.mark.parametrize("page", TUTORIALS)
def test_tutorial_runs_as_written(page, tmp_path):
    environment = {**os.environ, "PYTHONPATH": str(REPOSITORY),  # this checkout's flexff
                   "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}"}
    assert steps(page), page
    for name, block in steps(page):
        if name is not None:
            (tmp_path / name).write_text(block)
            continue
        done = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=tmp_path,
                              env=environment, capture_output=True, text=True)
        assert done.returncode == 0, f"{block}\n{done.stdout}{done.stderr}"
    for made, shown in FIGURE.findall(text(page)):
        image, plot = REPOSITORY / "docs" / "tutorials" / shown, tmp_path / made
        if os.environ.get("FLEXFF_TUTORIAL_FIGURES"):
            image.parent.mkdir(parents=True, exist_ok=True)
            Image.open(plot).convert("RGB").quantize(256, Image.Quantize.MAXCOVERAGE).save(
                image, optimize=True)
        assert Image.open(plot).size == Image.open(image).size, (made, shown)
