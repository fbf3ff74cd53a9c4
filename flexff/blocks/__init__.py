"""Generic loop blocks, free of any machine, each an fmu.system.System: a PID per axis (loop
shaping or explicit gains, notch, low-pass, anti-windup), sum and gain; registered as the
built-in FMUs "pid", "pid-gains", "sum" and "gain" (blocks.builtins)."""
