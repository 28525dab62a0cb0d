"""Where the model fails: the residual binned against the flown conditions
(:data:`~gainsched.constants.BIN_VARIABLES`) and the worst regime in words.
"""

from __future__ import annotations

import math

import numpy as np

from ...constants import BIN_VARIABLES
from ._axes import AT_NOISE_FLOOR, AXES, UNITS
from ._residual import Residual


def _bin_edges(var: str, x: np.ndarray, n_bins: int):
    if var == "azimuth":
        return np.linspace(0.0, 360.0, 13)
    if var == "tilt":
        vals = np.unique(np.round(x, 6))
        if vals.size <= 8:
            mids = (vals[1:] + vals[:-1]) / 2
            return np.concatenate([[vals[0] - 1], mids, [vals[-1] + 1]])
    lo, hi = np.percentile(x, [0.5, 99.5])
    if not hi > lo:
        return np.array([lo - 0.5, hi + 0.5])
    edges = np.linspace(lo, hi, n_bins + 1)
    edges[0], edges[-1] = min(lo, x.min()), max(hi, x.max()) + 1e-9
    return edges


def where_it_fails(res: list[Residual], noise: dict, n_bins: int = 8, min_count: int = 40) -> dict:
    """Residual binned against each of :data:`BIN_VARIABLES`, per axis, and the worst regime.

    Returns ``{"tables": {var: {"edges", "centers", "count", axis: {"rms", "bias"}}},
    "worst": {...}, "sentence": str}``. Bins with fewer than ``min_count`` samples are
    reported but not used to name the worst regime. The worst regime: the axis whose
    RMS is largest against its noise floor; for it the variable whose bins spread most;
    the sentence says whether the residual grows with the variable or concentrates in
    a range of it.
    """
    axes = [a for a in AXES if all(a in r.residual for r in res)]
    X = {v: np.concatenate([r.variables[v] for r in res]) for v in BIN_VARIABLES}
    E = {a: np.concatenate([r.residual[a] for r in res]) for a in axes}
    tables = {}
    for v in BIN_VARIABLES:
        edges = _bin_edges(v, X[v], n_bins)
        idx = np.clip(np.digitize(X[v], edges) - 1, 0, len(edges) - 2)
        count = np.bincount(idx, minlength=len(edges) - 1)
        centers = (edges[1:] + edges[:-1]) / 2
        if v == "tilt" and edges.size - 1 == np.unique(np.round(X[v], 6)).size:
            centers = np.unique(np.round(X[v], 6))  # one bin per flown tilt
        tab = {"edges": edges.tolist(), "centers": centers.tolist(), "count": count.tolist()}
        for a in axes:
            s2 = np.bincount(idx, E[a] ** 2, minlength=len(edges) - 1)
            s1 = np.bincount(idx, E[a], minlength=len(edges) - 1)
            with np.errstate(invalid="ignore", divide="ignore"):
                tab[a] = {"rms": np.sqrt(s2 / count).tolist(), "bias": (s1 / count).tolist()}
        tables[v] = tab
    # the worst axis relative to its noise floor
    ratio = {a: float(np.sqrt(np.mean(E[a] ** 2)) / noise.get(a, math.nan)) for a in axes}
    finite = {a: r for a, r in ratio.items() if np.isfinite(r)}
    worst_axis = max(finite, key=finite.get) if finite else axes[0]
    best = None
    for v in BIN_VARIABLES:
        tab = tables[v]
        cnt = np.array(tab["count"])
        rms = np.array(tab[worst_axis]["rms"])
        ok = cnt >= min_count
        if ok.sum() < 2:
            continue
        spread = float(np.nanmax(rms[ok]) / max(np.nanmin(rms[ok]), 1e-300))
        if best is None or spread > best[1]:
            best = (v, spread)
    out = {"tables": tables, "rms_over_noise": ratio, "worst": None, "sentence": ""}
    unit = UNITS[worst_axis]
    if finite and max(finite.values()) < AT_NOISE_FLOOR:
        out["worst"] = {"axis": worst_axis, "at_noise_floor": True}
        out["sentence"] = (
            f"every axis is within {AT_NOISE_FLOOR:g}x its noise floor (worst: {worst_axis}, "
            f"{ratio[worst_axis]:.2f}x): the model explains these flights down to the "
            "measurement noise"
        )
        return out
    if best is None:
        r_all = float(np.sqrt(np.mean(E[worst_axis] ** 2)))
        out["worst"] = {"axis": worst_axis}
        out["sentence"] = (f"{worst_axis} residual is the largest ({r_all:.3g} {unit} RMS, "
                           f"{ratio[worst_axis]:.1f}x its noise floor) and uniform over the "
                           "flown conditions")
        return out
    v, spread = best
    tab = tables[v]
    cnt = np.array(tab["count"])
    ok = cnt >= min_count
    rms = np.array(tab[worst_axis]["rms"])
    bias = np.array(tab[worst_axis]["bias"])
    centers = np.array(tab["centers"])
    edges = np.array(tab["edges"])
    vu = BIN_VARIABLES[v][0]
    iok = np.flatnonzero(ok)
    k = iok[np.nanargmax(rms[iok])]
    mid = 0.5 * (np.nanmax(rms[iok]) + np.nanmin(rms[iok]))
    high = iok[rms[iok] > mid]
    rank = np.corrcoef(np.arange(iok.size), rms[iok])[0, 1] if iok.size > 2 else 0.0
    others = iok[rms[iok] <= mid]
    r_low = float(np.sqrt(np.sum(rms[others] ** 2 * cnt[others]) / max(1, cnt[others].sum())))
    if v != "azimuth" and k == iok[-1] and rank > 0.7:
        trend = f"grows with {v} above {edges[high.min()]:.3g} {vu}"
    elif v != "azimuth" and k == iok[0] and rank < -0.7:
        trend = f"grows as {v} falls below {edges[high.max() + 1]:.3g} {vu}"
    else:
        lo, hi = edges[k], edges[k + 1]
        trend = f"concentrates at {v} {lo:.3g}-{hi:.3g} {vu}"
    out["worst"] = {"axis": worst_axis, "variable": v, "spread": spread,
                    "bin_center": float(centers[k]), "bin": [float(edges[k]), float(edges[k + 1])],
                    "rms": float(rms[k]), "bias": float(bias[k]),
                    "rms_elsewhere": r_low}
    out["sentence"] = (
        f"{worst_axis} residual {trend} (RMS {rms[k]:.3g} {unit}, bias {bias[k]:+.3g} {unit} "
        f"there vs {r_low:.3g} elsewhere; {ratio[worst_axis]:.1f}x the noise floor overall)"
    )
    if worst_axis in ("roll", "pitch") and v == "thrust" and trend.startswith("grows"):
        # a torque in proportion to the thrust: the thrust's line of action misses the COG
        out["sentence"] += (": a torque in proportion to the thrust, as a centre of mass "
                            "off the frame centre gives ([effects.cog_offset])")
    return out
