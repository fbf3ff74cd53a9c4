"""What `flexff fmu validate` refuses, `flexff run` refuses too (fmu.importer.read_fmu checks
the structure): a duplicate variable name, which would record one variable's values under
another's name, and a negative value reference each end a run before it starts, in one line
naming the fault."""

import pytest

from flexff.cli import main
from flexff.fmu.importer import FmuError, read_fmu
from flexff.fmu.validation import validate_fmu
from tests.fmu.test_validation import description, edited

FAULTS = {  # case: (edit of VanDerPol's modelDescription.xml, words of the one line)
    "duplicate name": (lambda t: t.replace('name="x1"', 'name="x0"'),
                       'The variable name "x0" (line 50) is not unique'),
    "negative value reference": (lambda t: t.replace('valueReference="5"',
                                                     'valueReference="-5"'),
                                 "attribute 'valueReference': '-5' is not a valid value"),
}


@pytest.mark.parametrize("case", FAULTS)
def test_run_refuses_what_validate_refuses(tmp_path, capsys, case):
    edit, words = FAULTS[case]
    fmu = edited("fmi2/VanDerPol.fmu", tmp_path / "faulty.fmu", description(edit))
    assert any(words in p for p in validate_fmu(fmu))
    with pytest.raises(FmuError, match="not a valid FMU"):
        read_fmu(fmu)
    config = tmp_path / "run.toml"
    config.write_text(f'[run]\nstep = 0.01\nstop = 1.0\n[fmu.m]\npath = "{fmu}"\n')
    code = main(["run", str(config), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err  # bad input
    assert len(err.splitlines()) == 1 and words in err, err
    assert err.startswith(f"flexff: error: {config}: fmu.m.path: {fmu}: modelDescription.xml: ")
    assert not (tmp_path / "out" / "signals.parquet").exists()
