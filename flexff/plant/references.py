"""The thesis's evaluation references of the manipulator: in simulation (sec. 5.7, 15 s) and on
the real machine (sec. 6.6, 100 s), built from plant.paths' segments; the [reference]
kinds `thesis-eval` and `thesis-hardware-eval` (registered by controllers.manipulator).
"""

from __future__ import annotations

import math

import numpy as np

from flexff.fmu.defaults import DEFAULT_STEP
from flexff.plant.paths import Chain, Circle, Hold, Line, Reference, sample

# evaluation reference of the thesis (section 5.7)
THESIS_LINE_END = (0.0098, -0.0098)
THESIS_LINE_TIME = 3.0
THESIS_RADIUS = 0.014
THESIS_TURNS = 11.5
THESIS_CIRCLE_TIME = 12.0
# evaluation reference of the thesis on the real machine (section 6.6)
THESIS_HW_LINE_END = (0.0082, 0.0082)
THESIS_HW_LINE_TIME, THESIS_HW_REST, THESIS_HW_CIRCLE_TIME, THESIS_HW_END = 21.0, 1.0, 75.0, 3.0
THESIS_HW_TURNS = 9.0


def thesis_evaluation_path() -> Chain:
    """The evaluation reference of the thesis (sec. 5.7), 15 s.

    A skew-sine line from the centre to (0.0098, -0.0098) m in 3 s, then 11.5 counter-clockwise
    turns of radius 0.014 m in 12 s. The line ends 0.01386 m from the centre, not 0.014, so the
    circle's centre is shifted by 0.1 mm along the -45 degree diagonal to start exactly there:
    the radius and the line's end point stay as given, and the path stays continuous.
    """
    end = np.array(THESIS_LINE_END)
    start_angle = math.atan2(end[1], end[0])
    centre = end - THESIS_RADIUS * np.array([math.cos(start_angle), math.sin(start_angle)])
    return Chain((Line((0.0, 0.0), THESIS_LINE_END, THESIS_LINE_TIME),
                  Circle(tuple(centre), THESIS_RADIUS, start_angle, THESIS_TURNS,
                         THESIS_CIRCLE_TIME)))


def thesis_evaluation(step: float = DEFAULT_STEP) -> Reference:
    """The thesis's evaluation reference sampled at `step`."""
    return sample(thesis_evaluation_path(), step)


def thesis_hardware_evaluation_path() -> Chain:
    """The thesis's evaluation reference on the real machine (sec. 6.6, Table 6.2), 100 s.

    A skew-sine line from the centre to (8.2, 8.2) mm in 21 s, 1 s at rest, 9 counter-clockwise
    turns about the centre in 75 s (0.12 Hz on average; the radius, 11.6 mm, is the line end's
    distance from the centre), 3 s at rest.
    """
    end = THESIS_HW_LINE_END
    return Chain((Line((0.0, 0.0), end, THESIS_HW_LINE_TIME), Hold(end, THESIS_HW_REST),
                  Circle((0.0, 0.0), math.hypot(*end), math.atan2(end[1], end[0]),
                         THESIS_HW_TURNS, THESIS_HW_CIRCLE_TIME),
                  Hold(end, THESIS_HW_END)))


def thesis_hardware_evaluation(step: float = DEFAULT_STEP) -> Reference:
    """The thesis's evaluation reference on the real machine sampled at `step`."""
    return sample(thesis_hardware_evaluation_path(), step)
