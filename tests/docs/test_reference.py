"""The reference pages cover what the code accepts: every key the configuration parser and
cosim.machine accept is in cosim.config_keys and on the page; every command is on the CLI page."""

import re

import pytest

from flexff.cli import build_parser
from flexff.cosim import machine
from flexff.cosim.builtins import registered
from flexff.cosim.config import parse_config
from flexff.cosim.config_error import ConfigError
from flexff.cosim.config_keys import all_keys, keys_of
from flexff.cosim.references import reference_kind_names
from flexff.plant.reference_kinds import SEGMENT_KINDS
from tests.helpers import REFERENCE_FMUS

FMU = {"a": {"path": str(REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"),
             "unconnected": "start"}}


def _accepted(data: dict) -> set[str]:
    """The keys the parser lists as known when it meets the unknown key `zz` in `data`."""
    with pytest.raises(ConfigError) as error:
        parse_config(data)
    known = re.search(r"known in \[.*?\]: (.*)\)$", str(error.value))
    assert known, str(error.value)
    return set(known.group(1).split(", "))


def _cases():
    yield "run", None, {"run": {"zz": 1}, "fmu": FMU}
    for kind in reference_kind_names():
        yield "reference", kind, {"reference": {"kind": kind, "radius": 0.01, "zz": 1},
                                  "fmu": FMU}
    for kind in SEGMENT_KINDS:
        yield "reference.segments[k]", kind, {
            "reference": {"kind": "segments", "segments": [{"kind": kind, "zz": 1}]},
            "fmu": FMU}
    for kind in ("constant", "csv"):
        yield "source", kind, {"fmu": FMU, "source": [{"kind": kind, "zz": 1}]}
    yield "fmu.NAME", "path", {"fmu": {"a": {**FMU["a"], "zz": 1}}}
    yield "connection", None, {"fmu": FMU, "connection": [{"from": "s", "to": "a.b", "zz": 1}]}
    yield "record", None, {"fmu": FMU, "record": {"zz": 1}}


@pytest.mark.parametrize(("table", "kind", "data"), list(_cases()),
                         ids=lambda v: v if isinstance(v, str) else "")
def test_the_key_table_lists_what_the_parser_accepts(table, kind, data):
    assert set(keys_of(table, kind)) == _accepted(data)


def test_a_builtin_accepts_the_common_keys_and_its_options():
    name, builtin = next(iter(registered().items()))
    accepted = _accepted({"fmu": {"a": {"builtin": name, "zz": 1}}})
    assert accepted - {o.key for o in builtin.options} == set(keys_of("fmu.NAME", "builtin"))


def test_the_key_table_lists_the_machine_description():
    for table, names in machine.KEYS.items():
        where = "machine" if table == "machine" else f"machine.{table}"
        assert set(keys_of(where)) == set(names), where


def test_every_key_and_builtin_has_an_entry_on_the_page(site):
    page = (site / "reference" / "configuration" / "index.html").read_text()
    for key in all_keys():
        assert f"<code>{key.name}</code>" in page, key
    for name, builtin in registered().items():
        assert f'builtin = "{name}"' in page.replace("&quot;", '"'), name
        for option in builtin.options:
            assert f"<code>{option.key}</code>" in page, (name, option.key)


def test_every_command_and_option_has_an_entry_on_the_cli_page(site):
    import gen_reference

    page = (site / "reference" / "cli" / "index.html").read_text()
    for words, parser, _ in gen_reference.commands(build_parser()):
        assert re.search(rf">flexff {' '.join(words)}<", page), words
        for action in parser._actions:
            for option in set(action.option_strings) - {"-h", "--help"}:
                assert f"<code>{option}</code>" in page, (words, option)


def test_config_example_help_lists_the_examples(capsys):
    from flexff.cli import main
    from flexff.cosim.example_configs import config_examples

    assert main(["config", "example", "--help"]) == 0
    shown = capsys.readouterr().out
    assert all(f"\n  {name}\n" in shown + "\n" for name in config_examples())


def test_every_api_object_has_an_entry_on_the_api_page(site):
    from flexff import api

    page = (site / "reference" / "api" / "index.html").read_text()
    for name in api.__all__:
        target = getattr(api, name)
        assert f'id="{target.__module__}.{target.__qualname__}"' in page, name


def test_data_collect_help_lists_the_library_s_trajectory_sets():
    from flexff.cli.shared import TRAJECTORY_SETS
    from flexff.learning.dataset import SETS

    assert TRAJECTORY_SETS == SETS


def test_the_reference_pages_hold_their_tables_as_the_code_makes_them():
    """The CLI, configuration and signal tables are in the repository's pages, current: after
    a change to the parser, the keys or the built-ins, `python docs/gen_reference.py`."""
    import gen_reference

    for page in gen_reference.PAGES:
        text = page.read_text()
        names = re.findall(r"<!-- end generated: ([a-z-]+) -->", text)
        assert names and set(names) <= set(gen_reference.REFERENCE), page.name
        assert gen_reference.refreshed(text) == text, (
            f"{page.name} is not current: run python docs/gen_reference.py")
