"""The identified rigid-body parameters as a file: what `flexff identify` writes and the
rigid-body feedforward FMU reads (run configurations' `identified = "file.json"`).

The file holds, besides the report of the identification (base parameters, uncertainties,
residual; learning.identify), `parameters`: the flat plant parameters that replace the nominal
model's in eq. (2.4), one value for each parameter the identification estimates. It is read
here, on the controllers' floor, so that a run configuration can name it without the learning
package; every problem is an InputError naming the file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from flexff.fmu.errors import InputError
from flexff.plant.parameters import NOMINAL

FORMAT = "flexff-identified-parameters"
VERSION = 1
# the fields whose flat parameters the identification estimates, in the order in which they
# lead a base parameter (learning.identify): the inertias, flexure stiffness and damping, and
# the motor friction; then the motors' torque constants relative to one another; the geometry
# and the centres of mass stay nominal
RIGID_BODY_FIELDS = ("j_up", "m_up", "j_rotor", "j_low", "m_low", "m_ee", "j_ee",
                     "k_s", "k_e", "k_w", "d_s", "d_e", "d_w")
FRICTION_FIELDS = ("tau_coulomb", "b_viscous")
IDENTIFIED_FIELDS = (*RIGID_BODY_FIELDS, *FRICTION_FIELDS, "w_stribeck", "k_t")
REDO = "write it again with flexff identify DATA -o DIR"


def identified_names() -> tuple[str, ...]:
    """The flat plant parameter names an identified-parameters file may set."""
    return tuple(NOMINAL.flat_values(*IDENTIFIED_FIELDS))


def write_identified(path: Path, parameters: Mapping[str, float],
                     report: Mapping[str, Any]) -> Path:
    """Write the deployable `parameters` with the identification's `report` to `path`."""
    content = {"format": FORMAT, "version": VERSION, "parameters": dict(parameters), **report}
    _checked(content, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(content, indent=2) + "\n", "utf-8")
    tmp.replace(path)
    return path


def read_identified(path: str | Path) -> dict[str, float]:
    """The flat plant parameters of an identified-parameters file, checked: an InputError
    names the file and what is wrong with it."""
    path = Path(path)
    try:
        content = json.loads(path.read_text("utf-8"))
    except OSError as error:
        raise InputError(f"{path}: cannot read the identified parameters "
                         f"({error.strerror or error})") from None
    except (ValueError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: not valid JSON ({error}); {REDO}") from None
    return _checked(content, path)


def _checked(content: Any, path: Path) -> dict[str, float]:
    if not isinstance(content, dict) or content.get("format") != FORMAT:
        raise InputError(f"{path}: not an identified-parameters file (format "
                         f"{FORMAT!r} expected); {REDO}")
    if content.get("version") != VERSION:
        raise InputError(f"{path}: version {content.get('version')!r}, this flexff reads "
                         f"version {VERSION}; {REDO}")
    parameters = content.get("parameters")
    if not isinstance(parameters, dict) or not parameters:
        raise InputError(f"{path}: 'parameters' must be a table of plant parameters; {REDO}")
    unknown = sorted(set(parameters) - set(identified_names()))
    if unknown:
        raise InputError(f"{path}: {unknown} are not identified parameters (known: "
                         f"{', '.join(identified_names())})")
    bad = [name for name, value in parameters.items()
           if isinstance(value, bool) or not isinstance(value, (int, float))
           or not math.isfinite(value)]
    if bad:
        raise InputError(f"{path}: parameters {bad} must be finite numbers")
    values = {name: float(value) for name, value in parameters.items()}
    try:
        NOMINAL.with_values(**values)
    except InputError as error:
        raise InputError(f"{path}: {error}") from None
    return values
