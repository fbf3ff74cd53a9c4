"""A stranger's plant FMU for the tests: three axes (one rotary, two linear, the last under
gravity) whose ports carry FMI array names, `force[1]..force[3]` in and `pos[1]..pos[3]` out,
with a quoted name `'tip speed'` beside them, and whose model structure declares no output
dependencies, as some tools export it (FMI: an output without a dependency list depends on
every input). Built by flexff's own builder, then its modelDescription.xml renamed.
"""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import casadi as ca

from flexff.fmu import build_fmu
from flexff.fmu.system import Parameter, System, Variable

AXES = 3
MASSES = (0.02, 2.0, 3.0)  # kg.m2 (rotary), kg, kg
DAMPING = 5.0  # per axis, in N.s/m (N.m.s/rad on the rotary one)
GRAVITY = 9.81  # m/s2 on the last axis
RENAMED = {**{f"F{k}": f"force[{k}]" for k in range(1, AXES + 1)},
           **{f"p{k}": f"pos[{k}]" for k in range(1, AXES + 1)}, "speed": "'tip speed'"}
REST = (0.0, 0.0, 0.0)


def plant_system() -> System:
    """m_k a_k = F_k - c v_k (- m_k g on the last axis); outputs the positions, the states."""
    x, u = ca.SX.sym("x", 2 * AXES), ca.SX.sym("u", AXES)
    p, w = ca.SX.sym("p", 1), ca.SX.sym("w", 0)
    acc = [(u[k] - DAMPING * x[AXES + k] - (MASSES[k] * GRAVITY if k == AXES - 1 else 0.0))
           / MASSES[k] for k in range(AXES)]
    return System(
        name="arrayplant", description="three axes with array-named ports", kind="continuous",
        states=(*(Variable(f"q{k}", "m") for k in range(1, AXES + 1)),
                *(Variable(f"v{k}", "m/s") for k in range(1, AXES + 1))),
        inputs=tuple(Variable(f"F{k}", "N") for k in range(1, AXES + 1)),
        outputs=(*(Variable(f"p{k}", "m") for k in range(1, AXES + 1)),
                 Variable("speed", "m/s")),
        parameters=(Parameter("unused", "1", start=0.0),),
        initial_state=ca.Function("x0", [p], [ca.DM(list(REST) + [0.0] * AXES)]),
        dynamics=ca.Function("f", [x, u, p], [ca.vertcat(*[x[AXES + k] for k in range(AXES)],
                                                         *acc)]),
        output=ca.Function("h", [x, u, p, w], [ca.vertcat(*[x[k] for k in range(AXES)],
                                                          x[AXES + 1])]),
        max_substep=2.5e-4)


def build_array_plant(folder: Path) -> Path:
    """The plant's FMU in `folder`, renamed, without output dependencies."""
    built = build_fmu(plant_system(), folder / "built.fmu")
    target = folder / "arrayplant.fmu"
    with zipfile.ZipFile(built) as source, zipfile.ZipFile(target, "w") as out:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                data = _renamed(data.decode()).encode()
            out.writestr(item, data)
    built.unlink()
    shutil.rmtree(folder / "built", ignore_errors=True)
    return target


def _renamed(xml: str) -> str:
    for old, new in RENAMED.items():
        xml = xml.replace(f'name="{old}"', f'name="{new.replace(chr(39), "&apos;")}"')
    xml = re.sub(r'(<Unknown index="\d+") dependencies="[^"]*"', r"\1", xml)
    return xml.replace('variableNamingConvention="flat"', 'variableNamingConvention="structured"')
