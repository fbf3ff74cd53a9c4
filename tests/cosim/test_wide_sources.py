"""A run with many source signals (a wide CSV table) sets up in time linear in its columns: the
master looks its signals up by name in tables, not by scanning its tuples once per column."""

import numpy as np
import pytest

from flexff.cosim.master import Master, ResolvedFmu
from flexff.cosim.wiring import Port, wire
from flexff.fmu.errors import InputError
from flexff.fmu.importer import read_fmu
from tests.helpers import REFERENCE_FMUS

FEEDTHROUGH = REFERENCE_FMUS / "fmi2" / "Feedthrough.fmu"


class CountedName(str):
    """A signal name that counts how often it is compared (a scan of a tuple of names compares
    with each, a table lookup with none but the one it finds, which is the name itself)."""

    compared = 0

    def __eq__(self, other: object) -> bool:
        CountedName.compared += 1
        return str.__eq__(self, other)

    __hash__ = str.__hash__


def wide_run(columns: int, steps: int = 3) -> tuple[dict, object]:
    """`columns` constant-per-column array sources beside the Feedthrough's input, all of
    them recorded (by full name, the Feedthrough's output by its own name)."""
    info = read_fmu(FEEDTHROUGH)
    sources = {CountedName(f"c{j}"): np.full(steps + 1, float(j)) for j in range(columns)}
    sources[CountedName("Float64_continuous_input")] = np.arange(steps + 1.0)
    links = wire([Port("ft", info, "start")], list(sources))
    with Master([ResolvedFmu("ft", FEEDTHROUGH, info=info)], list(sources), 0.1, links) as m:
        return sources, m.run(sources, steps, [*sources, "Float64_continuous_output"])


def test_a_wide_source_is_recorded_whole_and_right():
    sources, rec = wide_run(10_000)
    assert list(rec.signals) == [*sources, "Float64_continuous_output"]
    for name, values in sources.items():
        assert rec[name].tobytes() == values.tobytes(), name
    assert np.array_equal(rec["Float64_continuous_output"], np.arange(4.0))


def test_setting_up_a_wide_source_compares_each_name_a_bounded_number_of_times():
    """Before, each column's name was compared with every other's four times over (10^8
    comparisons at 10^4 columns, minutes at the 10^5 columns a CSV table may have)."""
    CountedName.compared = 0
    wide_run(2_000)
    assert CountedName.compared < 10 * 2_000


def test_names_still_resolve_by_their_own_name_or_fail_in_one_line():
    info = read_fmu(FEEDTHROUGH)
    sources = {"Float64_continuous_input": 0.0}
    fmus = [ResolvedFmu("a", FEEDTHROUGH, info=info), ResolvedFmu("b", FEEDTHROUGH, info=info)]
    links = wire([Port("a", info, "start"), Port("b", info, "start")], list(sources))
    with Master(fmus, list(sources), 0.1, links) as master:
        assert master.resolve("a.Float64_continuous_output") == "a.Float64_continuous_output"
        assert master.resolve("Float64_continuous_input") == "Float64_continuous_input"
        with pytest.raises(InputError, match=r"^signal 'Float64_continuous_output' is ambiguous: "
                                             r"a\.Float64_continuous_output, b\.Float64_cont"):
            master.resolve("Float64_continuous_output")
        with pytest.raises(InputError, match=r"^cannot record unknown signal 'z'; known: "):
            master.resolve("z")
