"""An FMU's log messages go to the run's log file as they come (cosim.fmu_log), and only the last
few stay in memory (fmu.messages): a chatty FMU's long run takes memory that does not grow with
its length, and an error still names the FMU's last messages."""

import pytest

from flexff.cosim.fmu_log import LOG_NAME, FmuLog
from flexff.cosim.master import CosimError, Master, ResolvedFmu
from flexff.cosim.run import run_config
from flexff.fmu.messages import TAIL
from tests.chatty_fmu import build_chatty

STEPS = 3_000


@pytest.fixture(scope="module")
def chatty(tmp_path_factory):
    return build_chatty(tmp_path_factory.mktemp("chatty"))


def test_every_message_is_written_and_only_a_tail_is_held(chatty):
    lines: list[str] = []
    with Master([ResolvedFmu("chatty", chatty)], [], 1e-3, log=lines.append) as master:
        master.run({}, STEPS)
        held = master._instances[0].messages
        assert held.count == STEPS and len(held.tail) == TAIL < STEPS
        assert held.last(2) == [line.partition(": ")[2] for line in lines[-2:]]
    assert len(lines) == STEPS
    assert lines[0].startswith("chatty: [OK] step 1 at t = 0 s: all is well ...")
    assert lines[-1].startswith(f"chatty: [OK] step {STEPS} at t = 2.999")


@pytest.mark.parametrize("isolate", [False, True])
def test_a_run_streams_its_fmu_log_into_its_folder_and_errors_name_the_last(chatty, tmp_path,
                                                                            isolate):
    """In-process or in its own process (the child keeps none: it relays each message)."""
    config = tmp_path / "chatty.toml"
    config.write_text(f'[run]\nstep = 0.001\nstop = {STEPS / 1000}\n'
                      f'[fmu.chatty]\npath = "{chatty}"\nparameters = {{ fail_at = 2.0 }}\n'
                      f'isolate = {str(isolate).lower()}\n')
    with pytest.raises(CosimError, match=r"^chatty: the step at t = 2 s failed: .*"
                                         r"\[Error\] step 2001 at t = 2 s: failing as asked"):
        run_config(config, tmp_path / "out")
    lines = (tmp_path / "out" / LOG_NAME).read_text().splitlines()
    assert len(lines) == 2001 and lines[-1] == ("chatty: [Error] step 2001 at t = 2 s: failing "
                                               "as asked")


def test_a_log_that_cannot_be_written_ends_without_stopping_the_run(tmp_path):
    log = FmuLog(tmp_path / LOG_NAME)
    log.write("a: [OK] kept")
    log._file.write = _no_space  # what a full disk does to the next write
    log.write("a: [OK] lost")
    log.write("a: [OK] lost too")
    with pytest.warns(UserWarning, match=rf"{LOG_NAME}: No space left on device: the FMUs' "
                                         rf"messages from there on are not in it$"):
        log.close()
    log.close()  # once
    log.write("a: [OK] after the run")  # an FMU freed late: dropped
    assert (tmp_path / LOG_NAME).read_text() == "a: [OK] kept\n"


def _no_space(text: str) -> int:
    raise OSError(28, "No space left on device")
