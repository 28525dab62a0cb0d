"""The certificate of one cell of the grid: its centre circle solved directly at twice
the azimuth samples against the runtime's interpolation from the cell's corners.

The errors at the azimuth midpoints (:func:`midpoint_errors`: gains as ``gainsched
check`` measures them, nominal thrusts and roll) and the loop closed along the centre
circle with the interpolated gains decide whether the automatic grid
(:mod:`gainsched.schedule.refine`, docs/grid.md) splits the cell. Errors are compared
in quanta of :data:`ERROR_QUANTUM`, so that last-bit differences never change the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..model.effects import registered_effects_context
from ..native.reproducible import ensure_blas_single_thread
from .grid import solve_circle
from .lqr import monodromy, spectral_radius

__all__ = ["ERROR_QUANTUM", "STABLE_RADIUS", "midpoint_errors",
           # the checks of cell centres the refinement runs (schedule/refine.py)
           "Centre", "check_centres", "quanta", "xi_linear"]

#: decisions compare errors rounded to this (a fraction: 0.01 %) with the bound less one
#: quantum, so that last-bit differences never change the grid
ERROR_QUANTUM = 1e-4
#: a midpoint loop counts as stable with a spectral radius below this
STABLE_RADIUS = 1.0 - 1e-6



def midpoint_errors(K, K_d, u, u_d, phi, phi_d, u_scale, phi_scale):
    """Relative errors of interpolated gains and nominal against directly solved ones.

    Parameters
    ----------
    K, K_d : ndarray, shape (m, 4, n)
        Interpolated and direct gains at m azimuths, N per state unit.
    u, u_d : ndarray, shape (m, 4)
        Interpolated and direct nominal thrusts, N.
    phi, phi_d : ndarray, shape (m,)
        Interpolated and direct nominal roll, rad.
    u_scale : float
        The circle's largest nominal thrust magnitude, N.
    phi_scale : float
        The circle's largest nominal roll magnitude, rad (0: the roll error is absolute).

    Returns
    -------
    gain, thrust, roll : ndarray, shape (m,)
        ``||K - K_d||_F / ||K_d||_F`` (as ``gainsched check``), ``max |u - u_d| /
        u_scale`` and ``|phi - phi_d| / phi_scale``.
    """
    gain = np.linalg.norm(K - K_d, axis=(-2, -1)) / np.linalg.norm(K_d, axis=(-2, -1))
    thrust = np.abs(u - u_d).max(-1) / u_scale
    roll = np.abs(phi - phi_d) / (phi_scale if phi_scale > 0 else 1.0)
    return gain, thrust, roll


def quanta(err: float) -> float:
    """An error in quanta of :data:`ERROR_QUANTUM`, rounded (inf stays inf)."""
    return round(err / ERROR_QUANTUM) if math.isfinite(err) else math.inf


@dataclass(frozen=True)
class Centre:
    """The certificate of one cell: worst errors over its azimuth midpoints, the closed
    loop along its centre circle with interpolated (``rho``) and direct gains, and the
    error of the azimuth interpolation alone (direct gains at the grid azimuths)."""

    gain: float = math.nan
    thrust: float = math.nan
    roll: float = math.nan
    azimuth: float = math.nan
    rho: float = math.nan
    rho_direct: float = math.nan

    @property
    def usable(self) -> bool:
        return math.isfinite(self.gain)

    @property
    def error(self) -> float:
        return max(self.gain, self.thrust, self.roll)


def xi_linear(X, xs):
    """Linear interpolation of samples ``X`` (n_xi, ...) at the uniform periodic azimuths
    onto the azimuths ``xs`` (rad), as the runtime interpolates along xi."""
    n_xi = X.shape[0]
    pos = np.mod(xs, 2 * np.pi) * (n_xi / (2 * np.pi))
    j = np.minimum(np.floor(pos).astype(int), n_xi - 1)
    w = (pos - j).reshape((-1,) + (1,) * (X.ndim - 1))
    return (1 - w) * X[j] + w * X[(j + 1) % n_xi]


def check_centres(config2, speed, tilts, corners, effects=(), dare_tilt0=True):
    """One certificate job: the centre circles of the cells at one mid speed.

    ``config2`` has twice the table's azimuth samples; ``tilts`` (rad) are the cells' mid
    tilts; ``corners[i]`` the four corner circles' ``(K (4, n_xi, 4, n), u_d (4, n_xi,
    4), phi_d (4, n_xi))``. Returns one :class:`Centre` per tilt (all NaN when the direct
    solve is infeasible)."""
    ensure_blas_single_thread()
    with registered_effects_context(effects):
        sol, steps = solve_circle(config2, speed, tilts, keep_steps=True, dare_tilt0=dare_tilt0,
                                  margins=False)
    ok = list(np.flatnonzero(np.isfinite(sol.spectral_radius)))
    out = []
    for i in range(len(tilts)):
        if i not in ok:
            out.append(Centre())
            continue
        K4, u4, phi4 = corners[i]
        K_d, u_d, phi_d = sol.K[i, 1::2], sol.u_d[i, 1::2], sol.phi_d[i, 1::2]
        u_scale, phi_scale = np.abs(sol.u_d[i]).max(), np.abs(sol.phi_d[i]).max()

        def mid(X):  # centre of the cell (speed x tilt weights 1/4) at the azimuth midpoints
            return 0.5 * (X + np.roll(X, -1, axis=1)).mean(axis=0)

        gain, thrust, roll = midpoint_errors(mid(K4), K_d, mid(u4), u_d, mid(phi4), phi_d,
                                             u_scale, phi_scale)
        az = midpoint_errors(mid(sol.K[i, None, 0::2]), K_d, mid(sol.u_d[i, None, 0::2]), u_d,
                             mid(sol.phi_d[i, None, 0::2]), phi_d, u_scale, phi_scale)
        out.append(Centre(float(gain.max()), float(thrust.max()), float(roll.max()),
                           float(max(e.max() for e in az)), math.nan,
                           float(sol.spectral_radius[i])))
    if ok:  # the loops closed with the interpolated gains, all tilts at once
        Ad, Bd, _ = steps
        N = Ad.shape[-3]
        xs = 2 * np.pi * np.arange(N) / N
        K_steps = np.stack([xi_linear(np.moveaxis(corners[i][0], 0, 1), xs).mean(axis=1)
                            for i in ok])
        rho = spectral_radius(monodromy(Ad, Bd, K_steps))
        for b, i in enumerate(ok):
            out[i] = replace(out[i], rho=float(rho[b]))
    return out
