"""Defaults that several packages share, each declared once and imported where it is used:
the communication step (1 ms, the thesis's 1 kHz Simulink Real-Time loop) is the step of a run,
of the FMUs flexff builds and of the references sampled for them."""

DEFAULT_STEP = 1e-3  # s: the communication step where none is given
