"""Effects outside the library that the simulator flies as truths: what a real vehicle
may have and no model of :mod:`gainsched.model.effects` describes (the campaigns'
hidden effects, :mod:`gainsched.sim.campaign`). Outside the registry, so diagnose never
offers them; the compiled plant (``gainsched/native/plant.c``) implements them, so a
campaign on them flies at the compiled plant's speed.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.effects import Effect, Param

__all__ = ["AzimuthThrustLoss"]


class AzimuthThrustLoss(Effect):
    """A thrust loss localised in azimuth (an effect *outside* the library, for tests).

    ``T *= 1 - depth exp(-(xi - xi0)^2 / (2 width^2))`` with xi the azimuth of the
    direction of travel (``atan2(-v_x, v_y)`` in C for positive circulation).
    """

    kind = "azimuth_thrust_loss"
    params = (
        Param("depth", "-", 0.0, 0.0, 0.9, "peak fractional thrust loss"),
        Param("xi0_deg", "deg", 90.0, -360.0, 360.0, "azimuth of the loss"),
        Param("width_deg", "deg", 20.0, 1.0, 180.0, "Gaussian width"),
    )

    def modify_thrust(self, T, kin, x):
        v = kin.v_C
        xi = np.arctan2(-v[..., 0], v[..., 1])
        d = (xi - math.radians(self.xi0_deg) + np.pi) % (2 * np.pi) - np.pi
        return T * (1 - self.depth * np.exp(-0.5 * (d / math.radians(self.width_deg)) ** 2))[
            ..., None
        ]
