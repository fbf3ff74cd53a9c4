"""Controllers, each described as an fmu.system.System: the feedback controller (PID loop
shaping per axis, notch, encoder kinematics and control allocation) and the rigid-body
feedforward of the nominal model."""
