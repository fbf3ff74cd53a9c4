"""The manipulator plant: parameters, kinematics, Lagrangian dynamics, actuators and sensors."""
