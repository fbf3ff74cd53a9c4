"""MkDocs hook: replaces `<!-- generated: NAME -->` in a page (with the block up to its end
marker, where the repository holds one: gen_reference) with the table NAME made from the code
(gen_reference) or from the commands' JSON (gen_results)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gen_reference
import gen_results

GENERATORS: dict[str, Callable[[], str]] = {
    **gen_reference.REFERENCE,
    "description-faults": gen_reference.faults_markdown,
    "results-demo": gen_results.demo_markdown,
    "results-bench": gen_results.bench_markdown,
    "results-processes": gen_results.processes_markdown,
    "results-training": gen_results.training_markdown,
    "results-machines": gen_results.machines_markdown,
}
MARKER = gen_reference.BLOCK  # a marker, or a marked block the repository holds


def on_page_markdown(markdown: str, **_: Any) -> str:
    """The page with each marker (or marked block) replaced by its generated Markdown."""
    return MARKER.sub(lambda m: GENERATORS[m.group(1)](), markdown)
