"""Reference tables generated from the code: the CLI from its argparse parser, the run
configuration's keys from cosim.config_keys, built-in FMUs' options from their registry.

The reference pages hold them in the repository, each between `<!-- generated: NAME -->` and
`<!-- end generated: NAME -->`, so that the pages read whole where Markdown is read (a clone,
the repository's web view); a test checks they are current, and `python docs/gen_reference.py`
writes them anew after a change. The site's build (hooks.py) generates them again.
"""

from __future__ import annotations

import argparse
import html
import re
from collections.abc import Callable, Iterator
from pathlib import Path

from flexff.cli import build_parser
from flexff.cosim.builtins import registered
from flexff.cosim.config_keys import all_keys, tables


def cell(text: object) -> str:
    """`text` fit for one cell of a Markdown table."""
    return html.escape(str(text), quote=False).replace("|", "&#124;").replace("\n", " ")


def code(text: object) -> str:
    """`text` as inline code fit for one cell of a Markdown table."""
    return f"<code>{cell(text)}</code>"


def commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
             ) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser, str]]:
    """Every command that runs something: (its words, its parser, its one-line help)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            for name, sub in action.choices.items():
                words = (*path, name)
                if any(isinstance(a, argparse._SubParsersAction) for a in sub._actions):
                    yield from commands(sub, words)
                else:
                    yield words, sub, helps.get(name, "")


def _option(action: argparse.Action) -> str:
    if not action.option_strings:
        return code(action.metavar or action.dest)
    return ", ".join(code(s) for s in action.option_strings)


def _default(action: argparse.Action) -> str:
    if action.required or action.default in (None, argparse.SUPPRESS) \
            or isinstance(action, (argparse._StoreTrueAction, argparse._HelpAction)):
        return ""
    default = action.default
    return code(" ".join(map(str, default)) if isinstance(default, list) else default)


def usage(parser: argparse.ArgumentParser) -> str:
    """The parser's usage, wrapped at 96 characters whatever the terminal."""
    formatter = argparse.HelpFormatter(parser.prog, width=96)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, "")
    return formatter.format_help().strip()


def cli_markdown() -> str:
    """The reference of every `flexff` command: usage, help and a table of its arguments."""
    parser = build_parser()
    out = ["Global option: `flexff --debug COMMAND ...` shows the Python traceback of an error.",
           ""]
    for words, sub, text in commands(parser):
        name = " ".join(words)
        out += [f"## flexff {name}", "", cell(text), "",
                "```text", usage(sub), *(["", sub.epilog] if sub.epilog else []), "```", "",
                "| argument | choices | default | meaning |", "|---|---|---|---|"]
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            choices = ", ".join(code(c) for c in action.choices or ())
            out.append(f"| {_option(action)} | {choices} | {_default(action)} | "
                       f"{cell(action.help or '')} |")
        out.append("")
    return "\n".join(out)


def config_markdown() -> str:
    """One table per table of the general form: key, type, default, unit, meaning."""
    out, every = [], all_keys()
    for table in tables():
        keys = [k for k in every if k.table == table]
        anchor = table.replace(".", "-").replace("[k]", "")
        bracket = f"[[{table}]]" if table in ("source", "connection", "machine.axis") \
            else f"[{table}]"
        kinds = any(k.kinds for k in keys)  # a column saying which kind a key is for
        out += [f"### `{bracket}` {{ #{anchor} }}", "",
                "| key | type | default | unit | meaning |" + (" for |" if kinds else ""),
                "|---|---|---|---|---|" + ("---|" if kinds else "")]
        out += [f"| {code(k.name)} | {cell(k.type)} | {cell(k.default)} | {cell(k.unit)} | "
                f"{cell(k.meaning)} |" + (f" {cell(', '.join(k.kinds))} |" if kinds else "")
                for k in keys]
        out.append("")
    return "\n".join(out)


def builtins_markdown() -> str:
    """The registered built-in FMUs and their options (keys of their [fmu.NAME] table)."""
    out = []
    for name, builtin in registered().items():
        out += [f"### `builtin = \"{name}\"`", "", cell(builtin.description) or "", "",
                "| option | type | default | choices |", "|---|---|---|---|"]
        for o in builtin.options:
            default = "required" if o.required else "" if o.default is None else code(o.default)
            choices = ", ".join(code(c) for c in o.choices)
            out.append(f"| {code(o.key)} | {o.kind} | {default} | {choices} |")
        out.append("")
    return "\n".join(out)


def signals_markdown() -> str:
    """The manipulator's signals as plant/signals.py declares them: name, unit, meaning."""
    from flexff.plant import signals

    groups = ("REFERENCE", "CURRENTS", "ENCODERS", "TORQUES", "TRUE_POSITION", "TRUE_VELOCITY",
              "FEEDFORWARD_FORCES", "CURRENT_FEEDFORWARD", "FEEDBACK_FORCES", "FORCES")
    out = ["| signal | unit | meaning |", "|---|---|---|"]
    for group in groups:
        out += [f"| {code(v.name)} | {cell(v.unit)} | {cell(v.description)} |"
                for v in getattr(signals, group)]
    return "\n".join(out) + "\n"


def faults_markdown() -> str:
    """The classes of model-description fault (fmu.description_faults.RULES): whether each
    stops a run, and why."""
    from flexff.fmu.description_faults import RULES, UNKNOWN

    out = ["| fault | a run | why |", "|---|---|---|"]
    out += [f"| {cell(r.name)} | {'stops' if r.fatal else 'warns'} | {cell(r.why)} |"
            for r in (*RULES, UNKNOWN)]
    return "\n".join(out) + "\n"


REFERENCE: dict[str, Callable[[], str]] = {
    "cli": cli_markdown, "config-keys": config_markdown, "builtins": builtins_markdown,
    "signals": signals_markdown,
}
PAGES = tuple(Path(__file__).parent / "reference" / name
              for name in ("cli.md", "configuration.md", "signals.md"))
# a block: its start marker alone, or the marker, its content and its end marker
BLOCK = re.compile(r"<!-- generated: ([a-z-]+) -->\n(?:.*?<!-- end generated: \1 -->\n)?",
                   re.DOTALL)


def refreshed(markdown: str) -> str:
    """The page with each block of REFERENCE generated anew between its markers."""
    def block(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in REFERENCE:
            return match.group(0)
        content = REFERENCE[name]().strip("\n")
        return (f"<!-- generated: {name} -->\n\n{content}\n\n"
                f"<!-- end generated: {name} -->\n")

    return BLOCK.sub(block, markdown)


def main() -> None:
    """Write each reference page's generated blocks anew."""
    for page in PAGES:
        text = page.read_text()
        if refreshed(text) != text:
            page.write_text(refreshed(text))
            print(f"wrote {page}")


if __name__ == "__main__":
    main()
