"""The property every input surface's fuzzer checks, and how long the fuzzers run.

A parser given any input either returns, or raises one of flexff's own error types (InputError,
RunError and their subclasses: ConfigError, FmuError, ...) with a non-empty message of one line,
within a time bound. Anything else is a bug: another exception escaping (a traceback at the
command line), a message the CLI cannot print as one line, or no answer within the bound (a
hang). Each example runs in-process under SIGALRM, so that a hang fails with its input instead
of stalling the test run.

The fast tests run a few dozen examples per surface in the default run; the slow ones
(`-m slow`) run for FLEXFF_FUZZ_SECONDS seconds per surface (default 600).
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

from hypothesis import HealthCheck, settings

from flexff.fmu.errors import InputError, RunError

OWN_ERRORS = (InputError, RunError)
HANG_SECONDS = 30.0  # no parse of a small input takes this long, even on a loaded machine
DEADLINE_MS = 10_000  # hypothesis's per-example deadline, generous on a shared machine
FAST_EXAMPLES = 40
SLOW_ROUND = 200  # examples per round of a slow fuzzer; rounds repeat until the time is spent
SUPPRESSED = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much,
              HealthCheck.function_scoped_fixture]


class Hang(BaseException):
    """A parse that did not answer within HANG_SECONDS (a BaseException, so that no parser's
    `except Exception` turns it into an error message)."""


def fuzz_seconds() -> float:
    """How long each slow fuzzer runs: FLEXFF_FUZZ_SECONDS, default 10 minutes."""
    return float(os.environ.get("FLEXFF_FUZZ_SECONDS", "600"))


def fast(examples: int = FAST_EXAMPLES) -> settings:
    """The settings of a fast fuzzer in the default run."""
    return settings(max_examples=examples, deadline=DEADLINE_MS,
                    suppress_health_check=SUPPRESSED)


def slow() -> settings:
    """The settings of one round of a slow fuzzer (no example database: each round is new)."""
    return settings(max_examples=SLOW_ROUND, deadline=DEADLINE_MS, database=None,
                    suppress_health_check=SUPPRESSED)


def run_for(seconds: float, fuzz_round: Callable[[], None]) -> None:
    """Run `fuzz_round` (a @given test of SLOW_ROUND examples) until `seconds` are spent, and
    say how many rounds ran (pytest -s shows it)."""
    start = time.monotonic()
    rounds = 0
    while rounds == 0 or time.monotonic() < start + seconds:
        fuzz_round()
        rounds += 1
    print(f"{rounds} rounds of up to {SLOW_ROUND} examples in {time.monotonic() - start:.0f} s")


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise Hang(f"no answer within {HANG_SECONDS} s")


def check(parse: Callable[[], Any]) -> Any:
    """`parse()`'s result, or None where it raised one of flexff's own errors with a one-line
    message; any other exception, a multi-line or empty message or a hang fails."""
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, HANG_SECONDS)
    try:
        return parse()
    except OWN_ERRORS as error:
        message = str(error)
        assert message.strip(), f"{type(error).__name__} without a message"
        assert message.splitlines() == [message], \
            f"{type(error).__name__} over several lines: {message!r}"
        return None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
