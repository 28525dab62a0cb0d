"""The residual's axes, their units and the noise-floor threshold: what every part of the
comparison names an axis by.
"""

from __future__ import annotations

#: Residual axes, in report order.
AXES = ("tangential", "normal", "radial", "roll", "pitch", "yaw", "stretch")
UNITS = {
    "tangential": "m/s^2",
    "normal": "m/s^2",
    "radial": "m/s^2",
    "roll": "rad/s^2",
    "pitch": "rad/s^2",
    "yaw": "rad/s^2",
    "stretch": "m",
}
#: the on-board sensor that measures a translational axis (the rotational: the gyro)
_SENSOR_OF = {"tangential": "accelerometer", "normal": "accelerometer",
              "radial": "accelerometer"}
#: RMS / noise floor below which an axis counts as explained down to the noise
AT_NOISE_FLOOR = 1.25
_INPUT_NAMES = ("T_C", "tau_x", "tau_y", "tau_z")
