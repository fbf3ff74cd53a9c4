"""Every expected failure of the command line is one line on stderr and the README's exit code
(0 ok, 1 a run that failed, 2 bad input, 130 interrupted), with a traceback only under
--debug. Most cases call flexff.cli.main in this process (faster, and patchable)."""

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flexff.cli import main
from flexff.cosim.master import CosimError
from tests.cosim.test_batch import SHORT  # a 1 s run of the manipulator

# commands that write, the output last: {out} is the output folder (or the output file's)
WRITERS = {
    "run": ["run", "{config}", "-o", "{out}"],
    "fmu build": ["fmu", "build", "plant", "-o", "{out}/plant.fmu"],
    "bench": ["bench", "--steps", "10", "-o", "{out}/bench.json"],
    "export": ["export", "{tmp}/no-run", "-o", "{out}/model.onnx"],
    "ssp export": ["ssp", "export", "{config}", "-o", "{out}/system.ssp"],
    "identify": ["identify", "{tmp}/no-data", "-o", "{out}"],
}


def _marked(command: str):
    """`command` as a parameter, marked learn where it needs PyTorch (export, identify)."""
    return pytest.param(command, marks=pytest.mark.learn) if command in ("export", "identify") \
        else command


COMMANDS = [_marked(c) for c in WRITERS]
FILE_COMMANDS = [_marked(c) for c in WRITERS if WRITERS[c][-1].startswith("{out}/")]


@pytest.fixture
def config(tmp_path) -> Path:
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    return path


@pytest.fixture
def read_only(tmp_path, monkeypatch) -> Path:
    """A folder where, as on a read-only file system, nothing can be created (tests run as
    root, for whom permissions do not stop writes)."""
    root = tmp_path / "ro"
    root.mkdir()
    real_mkdir, real_open = os.mkdir, os.open

    def inside(path) -> bool:
        return Path(os.fsdecode(path)).is_relative_to(root)

    def mkdir(path, *args, **kwargs):
        if inside(path):
            code = errno.EEXIST if os.path.exists(path) else errno.EROFS
            raise OSError(code, os.strerror(code), os.fsdecode(path))
        return real_mkdir(path, *args, **kwargs)

    def open_(path, flags, *args, **kwargs):
        if inside(path) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fsdecode(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    monkeypatch.setattr(os, "open", open_)
    return root


def fails(capsys, args: list, **fields) -> tuple[int, str]:
    """main(args) with {fields} filled in: its exit code and its one line on stderr."""
    code = main([str(a).format(**fields) for a in args])
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return code, err.strip()


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_under_a_file(capsys, tmp_path, config, command):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, line = fails(capsys, WRITERS[command], config=config, tmp=tmp_path,
                       out=blocker / "sub")
    assert (code, line) == (2, f"flexff: error: {blocker}: is a file, not a folder")


@pytest.mark.parametrize("command", FILE_COMMANDS)
def test_an_output_file_that_is_a_folder(capsys, tmp_path, config, command):
    """A file's name given as an existing folder (it was the atomic write's temporary file
    that the error named)."""
    args = WRITERS[command]
    target = Path(args[-1].format(out=tmp_path / "out"))
    target.mkdir(parents=True)
    code, line = fails(capsys, args, config=config, tmp=tmp_path, out=tmp_path / "out")
    assert (code, line) == (2, f"flexff: error: {target}: is a folder: give the name of the "
                               f"file to write")


def test_run_into_an_existing_file(capsys, tmp_path, config):
    (tmp_path / "results").write_text("")
    code, line = fails(capsys, WRITERS["run"], config=config, out=tmp_path / "results")
    assert (code, line) == (2, f"flexff: error: {tmp_path / 'results'}: is a file, not a "
                               f"folder")


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("existing", [True, False])
def test_an_output_on_a_read_only_file_system(capsys, tmp_path, config, read_only, command,
                                              existing):
    out = read_only if existing else read_only / "new"
    code, line = fails(capsys, WRITERS[command], config=config, tmp=tmp_path, out=out)
    assert (code, line) == (2, f"flexff: error: {out}: Read-only file system")


@pytest.mark.parametrize("args, text, message", [
    (["bench", "--steps", "0"], None, "bench steps must be a whole number of at least 1, got 0"),
    (["bench", "--realtime-seconds", "0"], None,
     "bench realtime seconds must be positive, got 0.0 (leave it out for the whole 100 s)"),
    (["run", "{config}", "-o", "{tmp}/out"], SHORT.replace("stop = 1.0", "stop = 1e7"),
     r"short.toml: run.stop, run.step: sampling the reference's 6 signals at 10000000001 "
     r"points needs 480,000 MB, more than the 16,000 MB of memory available: shorten run.stop"),
    (["run", "{config}", "-o", "{tmp}/out"], SHORT.replace("stop = 1.0", "step = 1e-9"),
     r"short.toml: run.step: sampling the 1 s reference every 1e-09 s needs 56,000 MB, more "
     r"than the 16,000 MB of memory available: a larger run.step"),
    (["run", "{config}", "-o", "{tmp}/out", "--sweep", "controller.encoders=2,3,2"], None,
     "the sweep lists the same value twice: 2"),
], ids=["bench-steps-0", "bench-realtime-0", "stop-1e7", "step-1e-9", "sweep-twice"])
def test_bad_input(capsys, monkeypatch, tmp_path, config, args, text, message):
    monkeypatch.setattr("flexff.cosim.memory.available_memory", lambda: 16 * 10**9)
    if text is not None:
        config.write_text(text)
    code, line = fails(capsys, args, config=config, tmp=tmp_path)
    assert code == 2 and line.startswith("flexff: error: ")
    assert message in line, line
    assert not (tmp_path / "out" / "signals.parquet").exists()


@pytest.mark.parametrize("error, message", [
    (CosimError("plant: fmi2DoStep at t = 0.5 s failed: the state is not finite"),
     "plant: fmi2DoStep at t = 0.5 s failed: the state is not finite"),
    (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "out/signals.npz"),
     "out/signals.npz: No space left on device"),
    (MemoryError("Unable to allocate 80 GiB"), "out of memory (Unable to allocate 80 GiB)"),
], ids=["cosim", "disk-full", "memory"])
def test_a_run_that_failed(capsys, monkeypatch, tmp_path, config, error, message):
    def run_config(*args, **kwargs):
        raise error

    monkeypatch.setattr("flexff.cosim.run.run_config", run_config)
    code, line = fails(capsys, WRITERS["run"], config=config, out=tmp_path / "out")
    assert (code, line) == (1, f"flexff: error: {message}")


def test_an_unreachable_scheduler(capsys, monkeypatch, tmp_path, config):
    monkeypatch.setattr("flexff.cosim.executor.SCHEDULER_TIMEOUT", "1s")
    code, line = fails(capsys, WRITERS["run"] + ["--scheduler", "tcp://127.0.0.1:9"],
                       config=config, out=tmp_path / "out")
    assert code == 1
    assert line.startswith("flexff: error: cannot reach the Dask scheduler at "
                           "tcp://127.0.0.1:9: "), line


def test_an_interrupted_run(capsys, monkeypatch, tmp_path, config):
    def run_config(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("flexff.cosim.run.run_config", run_config)
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == 130
    assert capsys.readouterr().err == (
        "flexff: interrupted; the runs that finished keep their folders, an interrupted run "
        "its record up to where it stopped; no file is left half-written\n")


@pytest.mark.parametrize("debug", [False, True])
def test_a_traceback_only_with_debug(capsys, monkeypatch, tmp_path, config, debug):
    """An unexpected error too is one line (naming it) without --debug."""
    def run_config(*args, **kwargs):
        raise KeyError("x_ref")

    monkeypatch.setattr("flexff.cosim.run.run_config", run_config)
    monkeypatch.setenv("FLEXFF_DEBUG", "0")  # restored after the test: --debug sets it
    args = ["--debug"] * debug + ["run", str(config), "-o", str(tmp_path / "out")]
    assert main(args) == 1
    err = capsys.readouterr().err
    hint = "" if debug else " (rerun with flexff --debug for the traceback)"
    assert err.endswith(f"flexff: error: KeyError: 'x_ref'{hint}\n")
    assert ("Traceback" in err) == debug


@pytest.mark.parametrize("debug", [False, True])
def test_a_batch_reports_one_line_per_failed_run(tmp_path, debug):
    """Two runs whose output folders are files: both fail, one line each (and their
    tracebacks under --debug, from the worker processes)."""
    out = tmp_path / "out"
    out.mkdir()
    for name in ("a", "b"):
        (tmp_path / f"{name}.toml").write_text(SHORT)
        (out / name).write_text("")
    env = {k: v for k, v in os.environ.items() if k != "FLEXFF_DEBUG"}
    result = subprocess.run([sys.executable, "-m", "flexff", *["--debug"] * debug, "run",
                             str(tmp_path / "a.toml"), str(tmp_path / "b.toml"), "-o", str(out),
                             "--workers", "2"], capture_output=True, text=True, env=env)
    assert result.returncode == 1
    failed = [line for line in result.stderr.splitlines() if ": FAILED: " in line]
    assert failed == [f"{n}: FAILED: NotADirectoryError: [Errno 20] is a file, not a folder: "
                      f"'{out / n}'" for n in ("a", "b")]
    assert ("Traceback" in result.stderr) == debug
    if not debug:
        assert len(result.stderr.splitlines()) == 2


def test_an_interrupted_batch(tmp_path):
    """Ctrl-C (SIGINT to the process group) during a batch of two workers: the runs in
    progress stop, the queued one never starts, one line and exit code 130."""
    long = SHORT.replace("stop = 1.0", "stop = 600.0").replace("circle_duration = 0.5",
                                                                "circle_duration = 599.5")
    out = tmp_path / "out"
    for name in "abc":
        (tmp_path / f"{name}.toml").write_text(long)
    process = subprocess.Popen(
        [sys.executable, "-m", "flexff", "run", *(str(tmp_path / f"{n}.toml") for n in "abc"),
         "-o", str(out), "--workers", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not ((out / "a").is_dir() and (out / "b").is_dir()):
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.1)
    time.sleep(0.3)  # into the runs (each takes seconds)
    os.killpg(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.splitlines()[-1] == (
        "flexff: interrupted; the runs that finished keep their folders, an interrupted run "
        "its record up to where it stopped; no file is left half-written")
    assert not (out / "c").exists()
