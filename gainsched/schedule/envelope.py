"""The flight envelope of a table: which circles (tilt, speed) have gains, and why not.

One category per circle of the grid, from the table's feasibility reasons and attitude
offsets (docs/table-format.md, "Feasibility reasons"), and a PNG of it over speed x tilt
with the lowest taut speed of each tilt (paper eq. 19) drawn in. ``gainsched inspect
--out DIR`` and the paper report (``gainsched paper``) show it.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from ..constants import Reason

__all__ = ["CATEGORIES", "Envelope", "envelope_from_table", "envelope_png", "envelope_figure",
           "write_envelope"]

#: circle categories, in the order of :attr:`Envelope.category`; a circle without gains
#: takes the first reason of the last four that any of its azimuths has
CATEGORIES = (
    "feasible",
    "feasible with attitude offsets",
    "trim failed",
    "tether slack",
    "thrust below minimum",
    "thrust above maximum",
)
_ORDER = (Reason.TRIM_FAILED, Reason.SLACK, Reason.THRUST_LOW, Reason.THRUST_HIGH)
_COLORS = ("tab:green", "tab:olive", "black", "tab:blue", "tab:red", "tab:purple")


@dataclass(frozen=True)
class Envelope:
    """Per-circle feasibility of a table.

    Attributes
    ----------
    name : str
        The table's config name.
    speed : ndarray, shape (n_v,), m/s
    tilt : ndarray, shape (n_a,), rad
    category : ndarray, shape (n_a, n_v), int
        Index into :data:`CATEGORIES`.
    max_offset : ndarray, shape (n_a, n_v), rad
        Largest ``|theta_d|``, ``|chi_d|`` of the circle's nominal (0 without offsets).
    taut_tilt : ndarray, shape (m,), rad
    taut_speed : ndarray, shape (m,), m/s
        Lowest constant speed keeping the configured tension margin at every azimuth
        (paper eq. 19) at tilts ``taut_tilt`` from 0 to the largest of the grid; empty
        if the table's config cannot be loaded here.
    """

    name: str
    speed: np.ndarray
    tilt: np.ndarray
    category: np.ndarray
    max_offset: np.ndarray
    taut_tilt: np.ndarray
    taut_speed: np.ndarray

    def counts(self) -> dict[str, int]:
        """Circles per category (categories with none left out)."""
        n = np.bincount(self.category.ravel(), minlength=len(CATEGORIES))
        return {c: int(k) for c, k in zip(CATEGORIES, n, strict=True) if k}

    def to_json(self) -> dict:
        """The envelope as plain JSON data (speeds m/s, tilts deg, category names)."""
        return {
            "speeds_mps": self.speed.tolist(),
            "tilts_deg": np.rad2deg(self.tilt).tolist(),
            "category": [[CATEGORIES[c] for c in row] for row in self.category],
            "max_attitude_offset_deg": np.rad2deg(self.max_offset).tolist(),
            "counts": self.counts(),
            "lowest_taut_speed": {"tilts_deg": np.rad2deg(self.taut_tilt).tolist(),
                                  "speeds_mps": self.taut_speed.tolist()},
        }


def _max_offsets(table) -> np.ndarray:
    """Largest |theta_d|, |chi_d| per circle (rad), sampled at 256 azimuths."""
    if table.offsets is None:
        return np.zeros(table.spectral_radius.shape)
    from .offsets import series

    xi = np.linspace(0.0, 2 * np.pi, 256, endpoint=False)
    coef = np.asarray(table.offsets, dtype=np.float64)
    out = np.zeros(coef.shape[:2])
    for idx in np.ndindex(*out.shape):
        val = series(np.broadcast_to(coef[idx], (xi.size, *coef.shape[2:])), xi)
        out[idx] = np.abs(val[:, [0, 2]]).max()
    return out


def envelope_from_table(table) -> Envelope:
    """The flight envelope of a loaded table.

    Parameters
    ----------
    table : Table
        A table from :func:`gainsched.schedule.tables.load_table`.

    Returns
    -------
    Envelope

    Example
    -------
    >>> env = envelope_from_table(load_table("tables/paper.h5"))   # doctest: +SKIP
    >>> env.counts()                                                # doctest: +SKIP
    {'feasible': 89, 'feasible with attitude offsets': 9, 'tether slack': 16}
    """
    from ..errors import InputError
    from .nominal import min_taut_speed
    from .tables import config_from_table

    has_gains = np.isfinite(table.spectral_radius)
    max_offset = _max_offsets(table)
    bits = np.bitwise_or.reduce(table.reasons, axis=-1)
    category = np.where(max_offset > 0, 1, 0)
    for k, bit in enumerate(_ORDER):
        hit = ~has_gains & (bits & bit).astype(bool) & (category < 2)
        category = np.where(hit, 2 + k, category)
    # a circle without gains and with no reason of its own (should not happen): trim failed
    category = np.where(~has_gains & (category < 2), 2, category)
    try:
        cfg = config_from_table(table)
    except InputError:
        taut_tilt = np.zeros(0)
    else:
        taut_tilt = np.linspace(0.0, float(np.max(table.tilt)), 41)
    taut = np.array([min_taut_speed(cfg, float(a)) for a in taut_tilt])
    return Envelope(table.name, np.asarray(table.speed, dtype=np.float64),
                    np.asarray(table.tilt, dtype=np.float64), category.astype(int),
                    max_offset, taut_tilt, taut)


def envelope_png(env: Envelope) -> bytes:
    """The envelope as a PNG image (:func:`envelope_figure`)."""
    import matplotlib.pyplot as plt

    fig = envelope_figure(env)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def envelope_figure(env: Envelope):
    """The envelope as a figure: one marker per circle of the grid over speed x tilt,
    coloured by category, with the lowest taut speed (paper eq. 19) as a line. The
    caller closes it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    tilt_deg = np.rad2deg(env.tilt)
    V, A = np.meshgrid(env.speed, tilt_deg)
    counts = env.counts()
    for k, name in enumerate(CATEGORIES):
        sel = env.category == k
        if sel.any():
            ax.scatter(V[sel], A[sel], marker="s", s=70, color=_COLORS[k],
                       label=f"{name} ({counts[name]})", zorder=3)
    if env.taut_tilt.size:
        ax.plot(env.taut_speed, np.rad2deg(env.taut_tilt), "k--", lw=1,
                label="lowest taut speed (paper eq. 19)", zorder=2)
    ax.set_xlabel("speed (m/s)")
    ax.set_ylabel("circle tilt alpha_C (deg)")
    with_gains = counts.get(CATEGORIES[0], 0) + counts.get(CATEGORIES[1], 0)
    ax.set_title(f"{env.name}: {with_gains} of {env.category.size} circles have gains "
                 f"({counts.get(CATEGORIES[1], 0)} with attitude offsets)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return fig


def write_envelope(table, source, out_dir) -> str:
    """Write envelope.png and envelope.json of a table into ``out_dir`` (one set, published
    at once: ``gainsched inspect -o``).

    Parameters
    ----------
    table : Table
        A table from :func:`gainsched.schedule.tables.load_table`.
    source : str or path-like
        Where the table was read from (the JSON's ``table``).
    out_dir : path-like
        The folder.

    Returns
    -------
    str
        The line that says what was written: the circles per category and the paths.
    """
    import json

    from ..publish import publish

    env = envelope_from_table(table)
    summary = {"table": str(source), "config": table.name, **env.to_json()}
    paths = publish(out_dir, {
        "envelope.png": envelope_png(env),
        "envelope.json": (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode(),
    }, where="--out")
    counts = ", ".join(f"{n} {c}" for c, n in env.counts().items())
    return f"  envelope: {counts} -> {', '.join(str(p) for p in paths)}"
