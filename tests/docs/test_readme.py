"""README.md stays short and keeps its two commands word for word."""

from tests.helpers import REPOSITORY

INSTALL = ('pip install -c .ci/constraints.txt -e ".[test]" && flexff demo   # install '
           'everything, run the main job')
TESTS = ("python -m pytest                             # run the tests (the heavy ones: "
         "python -m pytest -m slow)")


def test_readme_is_short_and_starts_with_the_two_commands():
    lines = (REPOSITORY / "README.md").read_text().splitlines()
    assert len(lines) <= 150
    assert lines[2:6] == ["```bash", INSTALL, TESTS, "```"]
