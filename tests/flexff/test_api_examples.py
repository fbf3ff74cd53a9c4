"""flexff.api: every function's docstring holds an example, and the examples run, in one folder
in ORDER (each using what the ones before made), on tiny settings."""

import doctest
import inspect
import shutil

from flexff import api
from flexff.cli import main
from tests.helpers import REPOSITORY

# runs before collects, collect before identify and train, evaluate before predict
ORDER = ("load", "check", "simulate", "run", "read", "sweep", "run_many", "register_builtin",
         "collect", "identify", "train", "export", "evaluate", "predict", "write_predictions",
         "ilc")


def test_every_function_has_an_example():
    functions = {name for name in api.__all__ if inspect.isfunction(getattr(api, name))}
    assert functions == set(ORDER)
    assert [name for name in ORDER if ">>> " not in (getattr(api, name).__doc__ or "")] == []


def test_the_examples_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["config", "example", "third-party-fmus"]) == 0
    (tmp_path / "run.toml").write_text(capsys.readouterr().out)
    for name in ("drive.toml", "drive-reference.csv"):
        shutil.copy(REPOSITORY / "flexff" / "machines" / "examples" / name, tmp_path)
    parser, runner = doctest.DocTestParser(), doctest.DocTestRunner()
    globs, report = {"api": api}, []
    for name in ORDER:
        test = parser.get_doctest(getattr(api, name).__doc__, globs, name, None, 0)
        runner.run(test, out=report.append, clear_globs=False)
        globs = test.globs  # the next example sees what this one made (DocTest copies them)
    assert runner.summarize(verbose=False).failed == 0, "".join(report)
    assert runner.summarize(verbose=False).attempted >= len(ORDER)
