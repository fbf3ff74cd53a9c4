"""Controllers: PID loop shaping, notch, control allocation, rigid-body feedforward (to come)."""
