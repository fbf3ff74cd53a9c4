"""run_in_child (fmu.child): a function run in a child process, what it sends checked.

- messages, a raised error and a return come back as JSON;
- a message longer than MESSAGE_LIMIT, or a pickle written onto the pipe by code in the child
  (as a hostile FMU could), ends the child with a protocol error, and nothing is unpickled.
"""

from __future__ import annotations

import os
import pickle
import struct
from pathlib import Path

from flexff.fmu.child import MESSAGE_LIMIT, run_in_child


def _talks(emit, text):
    emit(("said", text, None))
    raise ValueError("and then failed")


def _too_long(emit):
    emit("x" * MESSAGE_LIMIT)


class _Touch:
    """Unpickled, it creates a file: the mark of code run in the caller."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def _writes_a_pickle(emit, marker):
    payload = pickle.dumps(("emit", _Touch(marker)))
    for fd in os.listdir("/proc/self/fd"):
        try:
            if int(fd) > 2 and os.readlink(f"/proc/self/fd/{fd}").startswith("pipe:"):
                os.write(int(fd), struct.pack("!i", len(payload)) + payload)
        except OSError:
            pass  # the read end of a pipe, or listdir's own folder, closed since


def test_messages_and_an_error_come_back():
    end = run_in_child(_talks, ("hello",), 30.0)
    assert end.messages == [["said", "hello", None]]
    assert end.returned and end.error == "and then failed"


def test_a_message_over_the_limit_is_refused():
    end = run_in_child(_too_long, (), 30.0)
    assert end.error == "the FMU's process sent a message that is not the protocol's"
    assert end.messages == []


def test_a_pickle_on_the_pipe_is_never_unpickled(tmp_path):
    marker = tmp_path / "pwned"
    end = run_in_child(_writes_a_pickle, (str(marker),), 30.0)
    assert not marker.exists()
    assert end.error == "the FMU's process sent a message that is not the protocol's"
