"""The chatty FMU (tests/chatty_fmu.c): an honest FMI 2.0 co-simulation FMU that logs a message
of about 200 bytes every step (a long run's log must not stay in memory), and fails its step
from t >= fail_at on request."""

from __future__ import annotations

from pathlib import Path

from tests.probe_fmu import packaged_fmu

SOURCE = Path(__file__).with_suffix(".c")
DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="chatty" guid="{chatty}">
<CoSimulation modelIdentifier="chatty"/>
<ModelVariables>
<ScalarVariable name="clock" valueReference="0" causality="output" variability="discrete"
 initial="calculated"><Real/></ScalarVariable>
<ScalarVariable name="fail_at" valueReference="1" causality="parameter" variability="fixed">
 <Real start="-1.0"/></ScalarVariable>
</ModelVariables>
<ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs>
<InitialUnknowns><Unknown index="1"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""


def build_chatty(folder: Path) -> Path:
    """The chatty FMU in `folder`."""
    return packaged_fmu(folder, DESCRIPTION, SOURCE, "chatty")
