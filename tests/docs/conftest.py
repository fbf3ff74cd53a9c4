"""The documentation site, built once per test session with warnings as errors."""

import os
import subprocess
import sys

import pytest

from tests.helpers import REPOSITORY

sys.path.insert(0, str(REPOSITORY / "docs"))  # the generators: gen_reference, gen_results


@pytest.fixture(scope="session")
def site(tmp_path_factory):
    """The folder of the built site; the build fails on any warning (--strict)."""
    folder = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                           str(folder)], cwd=REPOSITORY, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stdout + done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    return folder
