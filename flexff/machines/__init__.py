"""Example machines beside the thesis's manipulator, each a description and the CasADi plant
flexff builds into an FMU: a 1-axis linear drive (`drive`) and a 2-axis stage with coupled axes
(`stage`). They are users' machines: they reach flexff only through its public path."""
