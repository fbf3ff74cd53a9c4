"""flexff: learned feedforward for a flexure manipulator, run as an FMI co-simulation.

The one import root: the floors flexff.fmu, flexff.plant, flexff.controllers, flexff.cosim and
flexff.learning (folders fmu/, plant/, ... at the repository root, linked from flexff/),
then the command line (flexff.cli).
"""

__version__ = "0.1.0"
