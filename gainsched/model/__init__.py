"""The physical model of the tethered quadcopter.

- :mod:`.rotations`: rotation matrices, Euler angles, quaternions.
- :mod:`.geometry`: the tether direction and its derivatives, attachment point and COG,
  pose to reduced angles and back (written once, used by every stage).
- :mod:`.effects`: the physical effects (drag, thrust change, motor lag, ...) with
  named parameters, the one place physics is added.
- :mod:`.reduced`: the reduced-coordinate dynamics, the tether tension and the one body
  wrench (paper Sec. II).
- :mod:`.thrustmap`: the thrust modifiers as a map from their input to the actual thrusts,
  and its inverse (the trim's commands).
- :mod:`.links`, :mod:`.maximal`: elastic tether links and the maximal-coordinate model
  of the simulator's plants.
- :mod:`.symmetry`: the exact symmetries of the scheduled problem (docs/symmetry.md).
"""
