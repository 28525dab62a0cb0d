"""The stability margins of a grid of loops as a user reads them: the worst of each and
where, as JSON data and as text (``gainsched inspect``, ``check``, the firmware header's
comment, ``check --uncertain``; docs/margins.md). The margins themselves are
:mod:`gainsched.schedule.margins`'."""

from __future__ import annotations

import numpy as np

from .margins import G_MAX, TAU_MAX_S, LoopMargins

__all__ = ["factor_db", "worst_margins", "worst_text", "worst_lines"]


def factor_db(factor):
    """A gain factor in dB, ``20 log10``; -inf for 0 (no lower margin), inf for inf.

    Parameters
    ----------
    factor : array_like
        Factors on the commands (``LoopMargins.gain_down``...).

    Returns
    -------
    ndarray
    """
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.asarray(factor, float))


def worst_margins(lm: LoopMargins, speeds, tilts) -> dict:
    """The worst margins of a grid of loops and where they are, as JSON data.

    Parameters
    ----------
    lm : LoopMargins
        Margins over (tilt, speed): arrays (n_a, n_v), per input (n_a, n_v, m).
    speeds : ndarray, shape (n_v,)
        The speed axis, m/s.
    tilts : ndarray, shape (n_a,)
        The tilt axis, rad.

    Returns
    -------
    dict
        ``circles`` (loops with margins) and, for ``gain_down``, ``gain_up``,
        ``input_down``, ``input_up`` (factors) and ``delay`` (s), the worst loop's
        ``value``, ``db`` (factors), ``speed_mps``, ``tilt_deg`` and, per input,
        ``input`` (its index). The worst is the value nearest to 1 (factors) or the
        smallest delay. ``value`` None: no crossing anywhere in the range searched (down:
        stable with the feedback off everywhere; up: beyond :data:`G_MAX`; delay: beyond
        :data:`TAU_MAX_S`); ``db`` None with it. An empty dict entry where no loop has
        margins. With crossovers (``lm.crossover``), ``phase``: the smallest phase margin
        at the crossover (:attr:`LoopMargins.phase`), its ``value`` (rad), ``deg``,
        ``crossover_rad_s`` and where (``value`` None: no crossover anywhere).

    Examples
    --------
    >>> lm = gs.LoopMargins(np.array([[0.2, 0.5]]), np.array([[np.inf, 4.0]]),
    ...                     np.zeros((1, 2, 1)), np.full((1, 2, 1), np.inf),
    ...                     np.array([[0.02, 0.01]]))
    >>> w = gs.worst_margins(lm, np.array([5.0, 10.0]), np.array([0.0]))
    >>> w["gain_down"]["value"], round(w["gain_down"]["db"], 2), w["gain_down"]["speed_mps"]
    (0.5, -6.02, 10.0)
    >>> w["gain_up"]["value"], w["input_down"]["value"], w["delay"]["value"]
    (4.0, None, 0.01)
    """
    ok = np.isfinite(lm.gain_down)
    out = {"circles": int(ok.sum())}
    for key, worse_is_larger, absent in (("gain_down", True, 0.0), ("gain_up", False, np.inf),
                                         ("input_down", True, 0.0), ("input_up", False, np.inf),
                                         ("delay", False, np.inf)):
        a = np.asarray(getattr(lm, key), float)
        mask = ok if a.ndim == 2 else ok[..., None] & np.ones(a.shape, bool)
        if not mask.any():
            out[key] = {}
            continue
        v = np.where(mask, a, -np.inf if worse_is_larger else np.inf)
        idx = np.unravel_index(np.argmax(v) if worse_is_larger else np.argmin(v), a.shape)
        x = float(a[idx])
        if x == absent:
            out[key] = {"value": None} | ({} if key == "delay" else {"db": None})
            continue
        entry = {"value": x, "speed_mps": float(speeds[idx[1]]),
                 "tilt_deg": float(np.rad2deg(tilts[idx[0]]))}
        if key != "delay":
            entry["db"] = float(factor_db(x))
        if a.ndim == 3:
            entry["input"] = int(idx[2])
        out[key] = entry
    if lm.crossover is not None:
        out["phase"] = _worst_phase(lm, ok, speeds, tilts)
    return out


def _worst_phase(lm: LoopMargins, ok, speeds, tilts) -> dict:
    """The ``phase`` entry of :func:`worst_margins`."""
    if not ok.any():
        return {}
    ph = np.where(ok & np.isfinite(lm.phase), lm.phase, np.inf)
    idx = np.unravel_index(np.argmin(ph), ph.shape)
    if not np.isfinite(ph[idx]):
        return {"value": None, "deg": None}
    return {"value": float(ph[idx]), "deg": float(np.degrees(ph[idx])),
            "crossover_rad_s": float(lm.crossover[idx]), "speed_mps": float(speeds[idx[1]]),
            "tilt_deg": float(np.rad2deg(tilts[idx[0]]))}


def worst_text(entry: dict, what: str, none: str, unit: str = "dB") -> str:
    """One worst margin of :func:`~gainsched.schedule.margin_report.worst_margins` as text."""
    if not entry:
        return f"{what} -"
    if entry["value"] is None:
        return f"{what} {none}"
    where = [f"x{entry['value']:.3g}"] if unit == "dB" else []
    if "input" in entry:
        where.append(f"T{entry['input'] + 1}")
    where.append(f"{entry['speed_mps']:g} m/s, tilt {entry['tilt_deg']:g} deg")
    value = f"{entry['db']:+.1f} dB" if unit == "dB" else f"{1e3 * entry['value']:.2f} ms"
    return f"{what} {value} ({'; '.join(where)})"


def worst_lines(w: dict, title: str) -> list[str]:
    """The worst margins of :func:`~gainsched.schedule.margin_report.worst_margins` as text: a
    title line, then all motors, one motor alone and the delay.

    Parameters
    ----------
    w : dict
        ``worst_margins(...)``.
    title : str
        What they are the margins of.

    Returns
    -------
    list of str
    """
    up = f"beyond +{20 * np.log10(G_MAX):.0f} dB"
    return [f"{title}, worst over the {w['circles']} circles (docs/margins.md):",
            "  all motors: " + worst_text(w["gain_down"], "down", "none (stable with the "
                                           "feedback off)") + "; "
            + worst_text(w["gain_up"], "up", up),
            "  one motor alone: " + worst_text(w["input_down"], "down", "none (stable with "
                                                "its feedback off)") + "; "
            + worst_text(w["input_up"], "up", up),
            "  " + worst_text(w["delay"], "extra delay", f"beyond {1e3 * TAU_MAX_S:g} ms",
                               unit="ms")] + _phase_line(w.get("phase"))


def _phase_line(entry) -> list[str]:
    """The phase margin's line of :func:`worst_lines` (none without crossovers)."""
    if entry is None:
        return []
    if not entry or entry["value"] is None:
        return ["  phase margin at the crossover: none (no delay crossing)"]
    return [f"  phase margin at the crossover {entry['deg']:.1f} deg at "
            f"{entry['crossover_rad_s']:.3g} rad/s ({entry['speed_mps']:g} m/s, tilt "
            f"{entry['tilt_deg']:g} deg)"]
