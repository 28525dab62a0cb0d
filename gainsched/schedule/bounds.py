"""The build's bounds on its closed loops: what they bought, what they cost, and the
refusal of a grid that breaks one (``[control] max_gain``, ``max_time_constant_s``).

A bound the LQR weights cannot be asked for directly is checked on the built grid and
refused in one line naming the config, the key and the circle that breaks it.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["check_gain_cap", "check_margin_bounds", "bound_price"]


def check_gain_cap(config, grid) -> None:
    """Refuse a grid whose gains exceed ``[control] max_gain`` anywhere.

    The price of a closed-loop bound (``max_time_constant_s``) or of large weights is
    gain: a cap says how much the vehicle can take (motor-command noise, saturation on
    the first error). Raises :class:`InputError` naming the config file, the key and the
    circle with the largest gain.

    Parameters
    ----------
    config : Config
        The config built (its ``control.max_gain``, N per state unit, or None: no cap).
    grid : GridResult
        The built grid.
    """
    cap = config.control.max_gain
    if cap is None:
        return
    k_max = grid.gain_max()
    if not np.nanmax(k_max, initial=0.0) > cap:
        return
    i, j = np.unravel_index(np.nanargmax(k_max), k_max.shape)
    bound = config.control.max_time_constant_s
    why = (f" with max_time_constant_s {bound:g} s ({grid.gain_max_free[i, j]:.3g} without "
           "the bound): raise max_gain or the bound" if bound is not None
           else ": raise max_gain or lower Q / raise R")
    raise InputError(config.source, "control.max_gain",
                     f"{cap:g} is exceeded: max |K| {k_max[i, j]:.3g} at "
                     f"{config.grid.speeds[j]:g} m/s, tilt {np.rad2deg(config.grid.tilts[i]):g} "
                     f"deg{why}")


def _where(config, i, j) -> str:
    return f"{config.grid.speeds[j]:g} m/s, tilt {np.rad2deg(config.grid.tilts[i]):g} deg"


def check_margin_bounds(config, grid) -> None:
    """Refuse a grid whose loops miss ``[control] min_gain_margin_db`` or
    ``min_delay_margin_ms`` (docs/margins.md).

    The gain bound holds for every margin of every feasible circle: all four motors and
    each alone, down and up, at least that many dB from 0 dB. Raises
    :class:`InputError` naming the config file, the key, the worst circle, the margin it
    reached and the weights that move it.

    Parameters
    ----------
    config : Config
        The config built (its ``control.min_gain_margin_db``, dB, and
        ``min_delay_margin_ms``, ms; None: no bound).
    grid : GridResult
        The built grid (its ``gain_margin``, ``input_margin`` and ``delay_margin``).
    """
    ctrl = config.control
    if ctrl.min_gain_margin_db is not None:
        with np.errstate(divide="ignore"):  # a factor 0 is no lower margin: inf dB
            dist = np.concatenate([-20 * np.log10(grid.gain_margin[..., :1]),
                                   20 * np.log10(grid.gain_margin[..., 1:]),
                                   -20 * np.log10(grid.input_margin[..., 0]),
                                   20 * np.log10(grid.input_margin[..., 1])], axis=-1)
        dist = np.where(np.isnan(dist), np.inf, dist)  # infeasible: no loop
        i, j, k = np.unravel_index(np.argmin(dist), dist.shape)
        if dist[i, j, k] < ctrl.min_gain_margin_db:
            m = grid.input_margin.shape[-2]
            what = (("all motors", "down"), ("all motors", "up"),
                    *((f"T{q + 1} alone", "down") for q in range(m)),
                    *((f"T{q + 1} alone", "up") for q in range(m)))[k]
            fix = ("raise Q or lower R (more feedback)" if what[1] == "down"
                   else "raise R or lower Q (softer gains)")
            raise InputError(config.source, "control.min_gain_margin_db",
                             f"{ctrl.min_gain_margin_db:g} dB is not met: the gain margin "
                             f"{what[1]} of {what[0]} is {dist[i, j, k]:.2f} dB at "
                             f"{_where(config, i, j)}: {fix}")
    if ctrl.min_delay_margin_ms is not None:
        ms = np.where(np.isnan(grid.delay_margin), np.inf, 1e3 * grid.delay_margin)
        i, j = np.unravel_index(np.argmin(ms), ms.shape)
        if ms[i, j] < ctrl.min_delay_margin_ms:
            raise InputError(config.source, "control.min_delay_margin_ms",
                             f"{ctrl.min_delay_margin_ms:g} ms is not met: the delay margin "
                             f"is {ms[i, j]:.2f} ms at {_where(config, i, j)}: raise R or "
                             "lower Q (a slower loop takes more delay)")


def bound_price(max_time_constant_s: float, grid) -> str:
    """One line: what ``[control] max_time_constant_s`` bought and what it cost.

    Parameters
    ----------
    max_time_constant_s : float
        The config's bound, s.
    grid : GridResult
        A grid built with it.

    Returns
    -------
    str
        The slowest closed-loop time constant of the grid against the bound, and the
        largest gain against the largest without the bound (N per state unit).
    """
    tau = grid.mode_tau[..., 0]
    if not np.any(np.isfinite(tau)):
        return f"max_time_constant_s {max_time_constant_s:g} s: no feasible circle"
    k_max = float(np.nanmax(grid.gain_max()))
    k_free = float(np.nanmax(grid.gain_max_free))
    return (f"max_time_constant_s {max_time_constant_s:g} s: slowest closed-loop mode "
            f"{np.nanmax(tau):.3g} s; the price: max |K| {k_max:.3g}, {k_free:.3g} without "
            f"the bound (x{k_max / k_free:.2f})")
