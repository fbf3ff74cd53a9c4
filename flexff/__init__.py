"""flexff: learned feedforward for a flexure manipulator, run as an FMI co-simulation."""

__version__ = "0.1.0"
