"""A hostile isolated FMU (the probe, tests/probe_fmu.c) against the sandbox (cosim.sandbox,
cosim/c/sandbox.c) and its master (cosim.isolation): each attack is stopped, or contained
with exit 1 and one line naming the FMU, and flexff never dies of a signal because of it.

- the terminal: input pushed with ioctl(TIOCSTI) (on /dev/tty, stdin, stdout, stderr) never
  reaches the user's shell, run under a pseudo-terminal;
- the memory shared with the master, shrunk: the master lives (no SIGBUS) and says so;
- a file's mode, times and extended attributes outside the scratch folder: unchanged;
- a cleared parent-death signal (it would outlive its master), a limit set on the master
  (its files' size: the record would fail to be written): stopped;
- stdout and stderr truncated and flooded: the user's log keeps what it had and takes at most
  a bounded amount, escaped, each line marked as the FMU's;
- threads, shared mappings and the scratch folder: bounded by the sandbox's limits;
- a spinning, stopped or hanging FMU (in fmi2Instantiate too) ends the run by itself;
- an FMU's log message with terminal escapes reaches the terminal escaped;
- a 64 MB reply on the pipe is refused in well under a second's reading;
- `flexff fmu validate` runs the FMU's code in the sandbox (a constructor that writes outside
  is stopped), unless --no-sandbox;
- sandbox_read confines what it reads, and an honest FMU reading only its own is bit-equal.
"""

from __future__ import annotations

import os
import pty
import select
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flexff.cli import main
from flexff.cosim import isolation, sandbox
from flexff.cosim.child_output import LIMIT_BYTES
from flexff.cosim.config import parse_config
from flexff.cosim.isolation import LENGTH, MESSAGE_LIMIT
from flexff.cosim.run import simulate_config
from flexff.fmu.importer import FmuError, read_fmu
from flexff.fmu.validation import validate_fmu
from tests.cosim.test_sandbox import _fake_child
from tests.helpers import REFERENCE_FMUS
from tests.probe_fmu import ATTEMPTS, ESCAPE, HANG_INSTANTIATE, INJECTED, OUTSIDE, build_probe

STEP = 0.1
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return build_probe(tmp_path_factory.mktemp("probe"), startTime=0.0, stopTime=1.0,
                       stepSize=STEP)


@pytest.fixture
def outside():
    """The file outside the scratch folder whose metadata the probe attempts to change."""
    path = Path(OUTSIDE)
    path.write_text("outside")
    path.chmod(0o644)
    os.utime(path, (1e9, 1e9))
    yield path
    path.unlink(missing_ok=True)


def write_config(folder: Path, probe: Path, attempt: str, name: str = "p", run: str = "",
                 extra: str = "", isolate: bool = True) -> Path:
    path = folder / "probe.toml"
    path.write_text(f'[run]\nstep = {STEP}\nstop = 1.0\n{run}\n[fmu.{name}]\npath = "{probe}"\n'
                    f'isolate = {str(isolate).lower()}\n{extra}\n'
                    f'parameters = {{ attempt = {ATTEMPTS.get(attempt, 0)}, attempt_at = 0.2 }}\n'
                    f'[[source]]\nkind = "constant"\nvalues = {{ u = 1.0 }}\n')
    return path


def run_flexff(folder: Path, config: Path, **kwargs) -> subprocess.CompletedProcess:
    """`flexff run` in a process of its own: the test lives if it dies of a signal."""
    return subprocess.run([sys.executable, "-m", "flexff", "run", str(config), "-o",
                           str(folder / "out")], cwd=folder, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, **kwargs)


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_input_pushed_into_the_terminal_never_reaches_it(tmp_path, probe):
    config = write_config(tmp_path, probe, "terminal")
    pid, terminal = pty.fork()
    if pid == 0:  # flexff with the pseudo-terminal as its controlling terminal and stdio
        os.chdir(tmp_path)
        os.environ["PYTHONPATH"] = str(ROOT)
        os.execv(sys.executable, [sys.executable, "-m", "flexff", "run", str(config), "-o",
                                  str(tmp_path / "out")])
    seen = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if select.select([terminal], [], [], 1.0)[0]:
            try:
                chunk = os.read(terminal, 4096)
            except OSError:  # the other end closed
                break
            if not chunk:
                break
            seen += chunk
    _, status = os.waitpid(pid, 0)
    os.close(terminal)
    text = seen.decode(errors="replace")
    assert INJECTED not in text  # what the line discipline echoes of pushed input
    assert os.waitstatus_to_exitcode(status) == 1, text
    assert "the sandbox stopped its process: it tried to push input into a terminal (ioctl " \
           "TIOCSTI)" in text


def test_the_shared_memory_cannot_be_shrunk_under_the_master(tmp_path, probe):
    done = run_flexff(tmp_path, write_config(tmp_path, probe, "shrink"), capture_output=True,
                      text=True)
    assert done.returncode == 1, (done.returncode, done.stderr)  # SIGBUS: -7
    err = done.stderr.strip()
    assert len(err.splitlines()) == 1 and err.startswith("flexff: error: p: the step at t = "
                                                         "0.2 s failed"), err


def test_the_masters_limits_cannot_be_changed(tmp_path, probe):
    done = run_flexff(tmp_path, write_config(tmp_path, probe, "limit_parent"),
                      capture_output=True, text=True)
    assert done.returncode == 1, (done.returncode, done.stderr)
    err = done.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert "the sandbox stopped its process: it tried to change the limits of process " in err
    assert "(prlimit64)" in err


@pytest.mark.parametrize("attempt, call", [("chmod", "chmod"), ("times", "utimensat"),
                                           ("xattr", "setxattr")])
def test_metadata_outside_the_scratch_folder_is_not_changed(tmp_path, probe, outside, attempt,
                                                            call, capsys):
    before = outside.stat()
    assert main(["run", str(write_config(tmp_path, probe, attempt)), "-o",
                 str(tmp_path / "out")]) == 1
    assert (f"the sandbox stopped its process: it tried to change a file's mode, owner, times "
            f"or attributes ({call} {OUTSIDE})") in one_line(capsys)
    after = outside.stat()
    assert stat.S_IMODE(after.st_mode) == 0o644 and after.st_mtime == before.st_mtime
    assert not os.listxattr(outside)


def test_clearing_the_parent_death_signal_is_stopped(tmp_path, probe, capsys):
    assert main(["run", str(write_config(tmp_path, probe, "orphan")), "-o",
                 str(tmp_path / "out")]) == 1
    assert ("the sandbox stopped its process: it tried to outlive flexff (prctl "
            "PR_SET_PDEATHSIG)") in one_line(capsys)


def test_the_users_log_is_neither_truncated_nor_flooded(tmp_path, probe):
    log = tmp_path / "log.txt"
    log.write_text("kept\n")
    with open(log, "a") as out:
        done = run_flexff(tmp_path, write_config(tmp_path, probe, "flood"), stdout=out,
                          stderr=out)
    text = log.read_bytes()
    assert done.returncode == 0, text[-2000:]
    assert text.startswith(b"kept\n")
    assert len(text) < 2 * LIMIT_BYTES  # of 20 MB written
    assert b"\x1b" not in text and b"\x07" not in text
    *lines, summary = text.decode().splitlines()[1:]
    assert "real-time factor" in summary  # flexff's own line, the last
    assert all(line.startswith("p| ") for line in lines), lines[:3]
    assert "p| flexff: error: forged" in lines
    assert lines[-1] == f"p| (its further output dropped: more than {LIMIT_BYTES} bytes)"


@pytest.mark.skipif(os.geteuid() == 0, reason="RLIMIT_NPROC does not bind root")
def test_threads_are_bounded(tmp_path, probe, capsys):
    assert main(["run", str(write_config(tmp_path, probe, "threads")), "-o",
                 str(tmp_path / "out")]) == 1
    assert "p: the step at t = 0.2 s failed" in one_line(capsys)


@pytest.mark.parametrize("attempt, extra", [("shared", "sandbox_memory = 256"),
                                            ("fill", "sandbox_scratch = 100")])
def test_shared_mappings_and_the_scratch_folder_are_bounded(tmp_path, probe, capsys, attempt,
                                                            extra):
    assert main(["run", str(write_config(tmp_path, probe, attempt, extra=extra)), "-o",
                 str(tmp_path / "out")]) == 1
    assert "p: the step at t = 0.2 s failed" in one_line(capsys)


@pytest.mark.parametrize("attempt", ["spin", "stop"])
def test_a_spinning_or_stopped_fmu_ends_the_run_by_the_default_timeout(tmp_path, probe, capsys,
                                                                       monkeypatch, attempt):
    monkeypatch.setattr(isolation, "STEP_TIMEOUT", 1.0)  # the default, shortened
    began = time.monotonic()
    assert main(["run", str(write_config(tmp_path, probe, attempt)), "-o",
                 str(tmp_path / "out")]) == 1
    assert time.monotonic() - began < 30
    assert ("p: the step at t = 0.2 s did not end within the step timeout of 1 s; its process "
            "was stopped") in one_line(capsys)


@pytest.mark.parametrize("run", ["step_timeout = 1", ""])
def test_a_hang_in_instantiate_ends_by_the_step_timeout(tmp_path, probe, capsys, monkeypatch,
                                                        run):
    monkeypatch.setattr(isolation, "STEP_TIMEOUT", 1.0)
    began = time.monotonic()
    config = write_config(tmp_path, probe, "nothing", name=HANG_INSTANTIATE, run=run)
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == 1
    assert time.monotonic() - began < 30
    assert (f"flexff: error: {HANG_INSTANTIATE}: instantiating it did not end within the step "
            f"timeout of 1 s; its process was stopped") in one_line(capsys)


@pytest.mark.parametrize("isolate", [True, False], ids=["isolated", "in-process"])
def test_an_fmu_log_message_reaches_the_terminal_escaped(tmp_path, probe, capsys, isolate):
    config = write_config(tmp_path, probe, "log", isolate=isolate)
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == 1
    err = one_line(capsys)
    assert "\x1b" not in err and "\x07" not in err
    assert r"\x1b[2J\x1b]0;owned\x07red\nflexff: forged" in err


def test_a_64_mb_reply_is_refused_fast(tmp_path):
    instance = _fake_child(tmp_path, LENGTH.pack(MESSAGE_LIMIT) + b"x" * MESSAGE_LIMIT)
    began = time.monotonic()
    with pytest.raises(FmuError, match="p: get failed: its process sent a message that is "
                                       "not the protocol's"):
        instance._response("get")
    assert time.monotonic() - began < 3  # 30 s, growing the reply by each chunk read
    os.close(instance._ack)


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """A probe that tries to write outside its folder when it is instantiated."""
    return build_probe(tmp_path_factory.mktemp("hostile"), hostile=True, startTime=0.0,
                       stopTime=1.0, stepSize=STEP)


def test_validate_runs_the_fmus_code_in_the_sandbox(hostile, capsys):
    Path(ESCAPE).unlink(missing_ok=True)
    assert main(["fmu", "validate", str(hostile)]) == 1
    out = capsys.readouterr().out
    assert ("error: running the FMU failed" in out or "the sandbox stopped" in out), out
    assert f"it tried to write to {ESCAPE}, outside its scratch folder" in out, out
    assert not Path(ESCAPE).exists()


def test_validate_without_the_sandbox_runs_it_free(hostile, capsys):
    """The opt-out, as `flexff run --no-sandbox`: the constructor writes where it likes."""
    Path(ESCAPE).unlink(missing_ok=True)
    try:
        assert main(["fmu", "validate", "--no-sandbox", str(hostile)]) == 0
        assert Path(ESCAPE).read_text() == "probe"
    finally:
        Path(ESCAPE).unlink(missing_ok=True)


@pytest.mark.parametrize("read, code", [(None, 0), ([], 1), ([OUTSIDE], 0)],
                         ids=["reads not confined", "sandbox_read = []", "the file given"])
def test_sandbox_read_confines_what_it_reads(tmp_path, probe, outside, capsys, read, code):
    extra = "" if read is None else f"sandbox_read = {read!r}".replace("'", '"')
    assert main(["run", str(write_config(tmp_path, probe, "read", extra=extra)), "-o",
                 str(tmp_path / "out")]) == code, capsys.readouterr().err


def test_a_reference_fmu_reading_only_its_own_is_bit_equal():
    fmus = {"vdp": {"path": str(REFERENCE_FMUS / "fmi3" / "VanDerPol.fmu")},
            "ft": {"path": str(REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"),
                   "unconnected": "start"}}
    run = {"run": {"step": 0.01, "stop": 1.0},
           "connection": [{"from": "vdp.x0", "to": "ft.Float64_continuous_input"}]}
    inside = simulate_config(parse_config({**run, "fmu": fmus}))
    confined = {name: {**fmu, "isolate": True, "sandbox_read": []} for name, fmu in fmus.items()}
    alone = simulate_config(parse_config({**run, "fmu": confined}))
    for name in inside.signals:
        assert np.array_equal(inside[name], alone[name]), name


@pytest.mark.parametrize("isolate, code", [(False, 0), (True, 1)],
                         ids=["in-process", "sandboxed"])
def test_the_masters_environment_cannot_be_read(tmp_path, probe, capsys, isolate, code):
    """/proc/PID/environ of the master (its secrets): Landlock refuses the sandboxed FMU."""
    config = write_config(tmp_path, probe, "environment", isolate=isolate)
    assert main(["run", str(config), "-o", str(tmp_path / "out")]) == code


def confine_and_record(folder: Path, report: int) -> None:
    """confine_checks, writing the layers that hold to $FLEXFF_TEST_HELD (opened before)."""
    out = os.open(os.environ["FLEXFF_TEST_HELD"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    held = sandbox.enter(isolation.library(), folder, sandbox.DEFAULT, report)
    os.write(out, "\n".join(held).encode())
    os.close(out)


def test_validate_holds_every_layer_an_isolated_run_holds(probe, tmp_path, monkeypatch):
    """Its process has one thread when it confines itself, so the namespaces hold too."""
    monkeypatch.setenv("FLEXFF_TEST_HELD", str(tmp_path / "held.txt"))
    assert validate_fmu(probe, confine=confine_and_record) == []
    held = (tmp_path / "held.txt").read_text().splitlines()
    with isolation.IsolatedInstance(read_fmu(probe), "p") as instance:
        assert set(held) == set(instance.held), held


def test_an_attempt_while_instantiating_ends_the_run_with_exit_1(tmp_path, hostile, capsys):
    Path(ESCAPE).unlink(missing_ok=True)
    assert main(["run", str(write_config(tmp_path, hostile, "nothing")), "-o",
                 str(tmp_path / "out")]) == 1  # the FMU's fault, not the input's: not 2
    assert (f"flexff: error: p: instantiating it failed: the sandbox stopped its process: it "
            f"tried to write to {ESCAPE}, outside its scratch folder") in one_line(capsys)
    assert not Path(ESCAPE).exists()


def test_a_hang_in_terminate_is_stopped_and_named(tmp_path, probe, capsys, monkeypatch):
    monkeypatch.setattr(isolation, "CLOSE_WAIT", 1.0)
    began = time.monotonic()
    assert main(["run", str(write_config(tmp_path, probe, "hang_terminate")), "-o",
                 str(tmp_path / "out")]) == 0  # the record is whole
    assert time.monotonic() - began < 30
    assert ("flexff: warning: p: terminating and freeing it did not end within 1 s; its "
            "process was stopped") in one_line(capsys)


def test_out_of_memory_the_kernel_ends_the_fmus_process_first(probe):
    with isolation.IsolatedInstance(read_fmu(probe), "p") as instance:
        pid = instance._process.pid
        assert Path(f"/proc/{pid}/oom_score_adj").read_text().strip() == "1000"
        assert os.getsid(pid) == pid != os.getsid(0)  # a session of its own: no terminal


def test_a_child_dying_while_its_pipe_closes_is_named(tmp_path, hostile, capsys, monkeypatch):
    """The child's pipe closes before its exit can be reaped (a kernel ends a process in that
    order): the master waits for it, not asks it again (that recursed: RecursionError)."""
    unreaped = subprocess.Popen.poll
    monkeypatch.setattr(subprocess.Popen, "poll",
                        lambda self: None if self.returncode is None else unreaped(self))
    Path(ESCAPE).unlink(missing_ok=True)
    assert main(["run", str(write_config(tmp_path, hostile, "nothing")), "-o",
                 str(tmp_path / "out")]) == 1
    assert (f"flexff: error: p: instantiating it failed: the sandbox stopped its process: it "
            f"tried to write to {ESCAPE}, outside its scratch folder") in one_line(capsys)
