"""The manipulator's controllers, each described as an fmu.system.System: the feedback
controller (PID loop shaping per axis around its centre axis, notch, encoder kinematics and
control allocation), the rigid-body feedforward of the nominal model, and the learned
feedforward (an exported ONNX model run by onnxruntime inside the FMU, its inputs from
`features`: the motion features of eq. 2.1). The generic loop blocks are in `blocks`."""
