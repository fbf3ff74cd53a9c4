"""Griffe extension: docstrings are plain text, so a `<name>` outside a code span is shown,
not read as an HTML tag, when mkdocstrings renders them as Markdown."""

from __future__ import annotations

import re
from typing import Any

import griffe

CODE_SPAN = re.compile(r"(`[^`]*`)")


def plain(text: str) -> str:
    """`text` with `<` written as an HTML entity outside its code spans."""
    parts = CODE_SPAN.split(text)
    return "".join(p if k % 2 else p.replace("<", "&lt;") for k, p in enumerate(parts))


class PlainDocstrings(griffe.Extension):
    """Escapes `<` in every docstring outside code spans."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)
