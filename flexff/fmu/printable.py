"""printable: text from an FMU (its log messages, what its process prints or reports) made safe
for a terminal: every character that is not printable (ESC and the other control characters,
line breaks, Unicode's format characters such as a right-to-left override) written as its
escape, and the whole cut to a length, so that an FMU can neither drive the user's terminal nor
write a line that passes for flexff's own."""

from __future__ import annotations


def printable(text: str, limit: int | None = None) -> str:
    """`text` with its unprintable characters escaped (`\\x1b`, `\\n`, `\\u202e`), cut to
    `limit` characters (None: whole) with an ellipsis where it was cut."""
    if limit is not None and len(text) > limit:
        text = text[:limit] + "…"
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)
