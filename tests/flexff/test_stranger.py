"""flexff as a stranger gets it (slow): a clone with nothing beside it passes the fast suite, and
the wheel installs into a fresh virtual environment and runs outside the checkout."""

import os
import subprocess
import sys

import pytest

from tests.helpers import REPOSITORY

pytestmark = pytest.mark.slow


def test_a_fresh_clone_with_nothing_beside_it_passes_the_fast_suite(tmp_path):
    clone = tmp_path / "alone" / "flexff"
    subprocess.run(["git", "clone", "--quiet", str(REPOSITORY), str(clone)], check=True)
    assert sorted(os.listdir(clone.parent)) == ["flexff"]
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-x"], cwd=clone, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert " passed" in done.stdout.splitlines()[-1] and "failed" not in done.stdout


def test_the_wheel_runs_outside_the_checkout():
    done = subprocess.run([str(REPOSITORY / ".ci" / "wheel")], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "CI: the wheel installs and runs outside the checkout" in done.stdout
