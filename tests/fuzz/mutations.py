"""Strategies shared by the fuzzers: a valid input's bytes mutated, structural garbage, and
values of every kind a parsed document (TOML tables, XML attributes) may hold instead of the
right one."""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

from hypothesis import strategies as st
from lxml import etree

# the values that break parsers most often: empty, huge, non-finite, odd types and characters
ODD_NUMBERS = [0, -1, 1, 2**31, 2**63 - 1, -(2**63), 1e-300, 1e300, 1e308, -0.0, 5e-324,
               math.inf, -math.inf, math.nan]
ODD_TEXTS = ["", " ", "0", "-1", "1e309", "nan", "inf", "-inf", "true", "0x10", "1_000", "١",
             "a.b", ".", "..", "/", "\x00", "\n", "line\nbreak", "é", "\u202e", "NaN",
             "1" * 400, "../../etc/passwd", "/dev/null", "/dev/zero", "C:\\x"]
XML_TEXTS = [t for t in ODD_TEXTS if t.isprintable() or t == "line\nbreak"]  # lxml takes these


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


@st.composite
def mutated_xml(draw: st.DrawFn, tree: etree._Element, tags: Sequence[str],
                attributes: Sequence[str], values: Sequence[str]) -> bytes:
    """The XML document `tree` with one to four edits: an element removed, repeated or given
    another of `tags`, one of `attributes` set to one of `values` or to odd text, or an
    attribute removed."""
    root = copy.deepcopy(tree)
    text = st.text(st.characters(min_codepoint=32, max_codepoint=0xFFFD,
                                 exclude_categories=["Cs"]), max_size=12)  # XML's characters
    for _ in range(draw(st.integers(1, 4))):
        element = draw(st.sampled_from([e for e in root.iter() if isinstance(e.tag, str)]))
        edit = draw(st.sampled_from(["remove", "repeat", "rename", "set", "unset"]))
        parent = element.getparent()
        if edit == "remove" and parent is not None:
            parent.remove(element)
        elif edit == "repeat" and parent is not None:
            parent.append(copy.deepcopy(element))
        elif edit == "rename":
            element.tag = draw(st.sampled_from(tags))
        elif edit == "set":
            element.set(draw(st.sampled_from(attributes)),
                        draw(st.one_of(st.sampled_from(values), text)))
        elif element.attrib:
            del element.attrib[draw(st.sampled_from(sorted(element.attrib)))]
    return bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
