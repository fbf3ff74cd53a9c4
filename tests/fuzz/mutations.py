"""Strategies shared by the fuzzers: a valid input's bytes mutated, structural garbage, and
values of every kind a parsed document (TOML tables, XML attributes) may hold instead of the
right one."""

from __future__ import annotations

import math
from typing import Any

from hypothesis import strategies as st

# the values that break parsers most often: empty, huge, non-finite, odd types and characters
ODD_NUMBERS = [0, -1, 1, 2**31, 2**63 - 1, -(2**63), 1e-300, 1e300, 1e308, -0.0, 5e-324,
               math.inf, -math.inf, math.nan]
ODD_TEXTS = ["", " ", "0", "-1", "1e309", "nan", "inf", "-inf", "true", "0x10", "1_000", "١",
             "a.b", ".", "..", "/", "\x00", "\n", "line\nbreak", "é", "\u202e", "NaN",
             "1" * 400, "../../etc/passwd", "/dev/null", "/dev/zero", "C:\\x"]


def odd_scalars() -> st.SearchStrategy[Any]:
    """A value of any scalar TOML type, the odd ones preferred."""
    return st.one_of(st.sampled_from(ODD_NUMBERS), st.sampled_from(ODD_TEXTS), st.booleans(),
                     st.integers(), st.floats(), st.text(max_size=20))


def odd_values() -> st.SearchStrategy[Any]:
    """A TOML value: a scalar, or lists and tables of them, nested a little."""
    return st.recursive(odd_scalars(), lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
        max_leaves=8)


@st.composite
def mutated_bytes(draw: st.DrawFn, valid: bytes) -> bytes:
    """`valid` with a few random edits: bytes flipped, inserted, deleted, a span repeated or
    cut off."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(data)))
        edit = draw(st.sampled_from(["flip", "insert", "delete", "repeat", "truncate"]))
        if edit == "flip" and at < len(data):
            data[at] = draw(st.integers(0, 255))
        elif edit == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=8))
        elif edit == "delete":
            del data[at:at + draw(st.integers(1, 16))]
        elif edit == "repeat":
            span = data[at:at + draw(st.integers(1, 64))]
            data[at:at] = span * draw(st.integers(1, 50))
        elif edit == "truncate":
            del data[at:]
    return bytes(data)


def mutated_text(valid: str) -> st.SearchStrategy[str]:
    """`valid` with a few random edits, as text (invalid UTF-8 replaced)."""
    return mutated_bytes(valid.encode()).map(lambda b: b.decode("utf-8", "replace"))


def garbage() -> st.SearchStrategy[bytes]:
    """Structural garbage: random bytes, or random text."""
    return st.one_of(st.binary(max_size=512), st.text(max_size=512).map(str.encode))
