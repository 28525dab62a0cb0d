"""Plots of one simulated flight (``gainsched simulate``, the paper report).

:func:`tracking_errors` computes what the plots draw, from a
:class:`~gainsched.sim.loop.SimResult`: the speed error, the along-track error (how far
the vehicle runs ahead of the reference azimuth, in metres along the circle) and the
out-of-plane error (the COG's distance from the circle plane). :func:`plot_result`
writes ``speed_roll.png`` (speed with its error panel, the along-track error, roll) and
``path3d.png`` (the path in 3-D at equal scale on every axis, beside the out-of-plane
error over azimuth, where a flat circle shows as a flat line rather than a corkscrew).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.geometry import wrap_angle
from ..rotations import R_IC_from_tilt

__all__ = ["tracking_errors", "plot_result", "left_table_intervals"]


def tracking_errors(res) -> dict:
    """The tracking errors of a simulated flight, by name, one sample per control step.

    Parameters
    ----------
    res : SimResult
        A flight (:func:`gainsched.simulate`), N samples.

    Returns
    -------
    dict of str to ndarray, each shape (N,)
        ``speed_mps`` simulated minus desired tangential COG speed, m/s;
        ``along_track_m`` ``r wrap(xi - xi_ref)``: positive ahead of the reference, m;
        ``out_of_plane_m`` the COG's distance from the circle plane (along its normal
        ``R_IC e_z``), m; ``azimuth_deg`` the azimuth xi in [0, 360), deg.

    Examples
    --------
    >>> import dataclasses
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=1.0)
    >>> res = gs.simulate(cfg, gs.table_scheduler(gs.load_table("tables/paper.h5")), scn)
    >>> errors = gs.tracking_errors(res)
    >>> sorted(errors), errors["out_of_plane_m"].shape
    (['along_track_m', 'azimuth_deg', 'out_of_plane_m', 'speed_mps'], (1001,))
    >>> bool(abs(errors["out_of_plane_m"]).max() < 0.05)   # m, from a 0.01 rad start
    True
    """
    n_I = R_IC_from_tilt(res.scenario.tilt, res.scenario.gamma)[:, 2]
    return {
        "speed_mps": (res.z[:, 3] - res.z_d[:, 3]) * res.r,
        "along_track_m": res.r * wrap_angle(res.z[:, 1] - res.z_d[:, 1]),
        "out_of_plane_m": res.p_I @ n_I,
        "azimuth_deg": np.rad2deg(res.z[:, 1]) % 360.0,
    }


def left_table_intervals(res) -> dict:
    """Where a flight left its table, as time intervals ``[(t0, t1), ...]`` (s) per cause:
    ``"clamped speed"`` (the lookup's speed clamped to the table's range), ``"held
    gains"`` (no usable gains: the last good ones flown) and ``"tension below margin"``
    (the nominal's tension under ``feasibility.min_tension``); the same samples
    :func:`~gainsched.sim.loop.metrics` counts, each interval closed at the next sample."""
    from ..firmware.runtime import CLAMPED_SPEED

    masks = {"clamped speed": (np.asarray(res.status) & CLAMPED_SPEED) != 0}
    if res.held is not None:
        masks["held gains"] = np.asarray(res.held, dtype=bool)
    if res.tension_d is not None:
        masks["tension below margin"] = np.asarray(res.tension_d) < res.min_tension
    dt = float(res.t[1] - res.t[0]) if res.t.size > 1 else 0.0
    out = {}
    for cause, m in masks.items():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], m.astype(np.int8), [0]])))
        out[cause] = [(float(res.t[a]), float(res.t[b - 1]) + dt)
                      for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return out


#: shading of :func:`left_table_intervals` in the time plots
_SHADES = {"clamped speed": "tab:orange", "held gains": "tab:red",
           "tension below margin": "tab:purple"}


def plot_result(res, out_dir) -> list[Path]:
    """Plot a simulated flight: speed, tracking errors and roll; the 3-D path.

    Two PNG files (matplotlib, Agg backend):

    - ``speed_roll.png``: the speed (desired and simulated, m/s) with its error panel,
      the along-track error (cm; positive ahead of the reference) and the roll angle
      (nominal and simulated, deg) over time, each error panel with its RMS; the times
      the flight left its table shaded (:func:`left_table_intervals`);
    - ``path3d.png``: the COG path in the inertial frame at equal scale on every axis
      (m), beside the out-of-plane error (mm) over the azimuth (deg), where a flat
      circle shows as a flat line rather than a corkscrew.

    The errors are those of :func:`tracking_errors`.

    Parameters
    ----------
    res : SimResult
        A simulated flight (:func:`~gainsched.sim.loop.simulate`).
    out_dir : str or path-like
        An existing directory; files of the same names in it are replaced.

    Returns
    -------
    list of Path
        ``[out_dir / "speed_roll.png", out_dir / "path3d.png"]``.

    Examples
    --------
    >>> import dataclasses, tempfile
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> table = gs.load_table("tables/paper.h5")
    >>> scn = dataclasses.replace(gs.load_scenario("horizontal"), duration=0.5)
    >>> res = gs.simulate(cfg, gs.table_scheduler(table), scn)
    >>> out = tempfile.mkdtemp()
    >>> [p.name for p in gs.plot_result(res, out)]
    ['speed_roll.png', 'path3d.png']
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    err = tracking_errors(res)
    paths = [out_dir / "speed_roll.png", out_dir / "path3d.png"]
    for draw, path in zip((_speed_roll, _path3d), paths, strict=True):
        fig = draw(plt, res, err)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
    return paths


def _speed_roll(plt, res, err):
    """speed_roll.png of :func:`plot_result`: speed, its error, along-track error, roll."""
    name = res.scenario.name
    v, v_ref = res.z[:, 3] * res.r, res.z_d[:, 3] * res.r
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    fig, ax = plt.subplots(4, 1, figsize=(8, 8.5), sharex=True,
                           gridspec_kw={"height_ratios": [2, 1, 1, 2]})
    ax[0].plot(res.t, v_ref, "r", label="desired")
    ax[0].plot(res.t, v, "b", label="simulated")
    ax[0].set_ylabel("speed (m/s)")
    ax[0].legend()
    ax[1].plot(res.t, err["speed_mps"], "k", lw=0.8)
    ax[1].axhline(0.0, color="0.6", lw=0.5)
    ax[1].set_ylabel(f"speed error (m/s)\nRMS {rms(err['speed_mps']):.3g}", fontsize=8)
    ax[2].plot(res.t, 100 * err["along_track_m"], "k", lw=0.8)
    ax[2].axhline(0.0, color="0.6", lw=0.5)
    ax[2].set_ylabel(f"along-track error (cm)\nRMS {100 * rms(err['along_track_m']):.3g}",
                     fontsize=8)
    ax[3].plot(res.t, np.rad2deg(res.z_d[:, 4]), "r", label="nominal")
    ax[3].plot(res.t, np.rad2deg(res.z[:, 4]), "b", label="simulated")
    ax[3].set_ylabel("roll phi (deg)")
    ax[3].set_xlabel("time (s)")
    ax[3].legend()
    ax[0].set_title(f"{name}: speed, along-track error (ahead of the reference: > 0) and roll")
    for cause, spans in left_table_intervals(res).items():
        for k, (t0, t1) in enumerate(spans):
            for a in ax:
                a.axvspan(t0, t1, color=_SHADES[cause], alpha=0.15, lw=0,
                          label=f"{cause} (left the table)" if a is ax[0] and k == 0 else None)
    if any(left_table_intervals(res).values()):
        ax[0].legend(fontsize=7)
    return fig


def _path3d(plt, res, err):
    """path3d.png of :func:`plot_result`: the 3-D path and the out-of-plane error."""
    name = res.scenario.name
    fig = plt.figure(figsize=(12, 5.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    p = res.p_I
    ax3.plot(p[:, 0], p[:, 1], p[:, 2], lw=0.8)
    # equal scale on every axis: a flat circle looks flat (matplotlib scales each to fit)
    mid = 0.5 * (p.max(0) + p.min(0))
    half = 0.5 * float(np.max(p.max(0) - p.min(0))) or 1.0
    ax3.set_xlim(mid[0] - half, mid[0] + half)
    ax3.set_ylim(mid[1] - half, mid[1] + half)
    ax3.set_zlim(mid[2] - half, mid[2] + half)
    ax3.set_box_aspect((1, 1, 1))
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.set_title(f"{name}: COG path (inertial frame, equal scale)")
    ax = fig.add_subplot(1, 2, 2)
    ax.plot(err["azimuth_deg"], 1000 * err["out_of_plane_m"], ".", ms=1.5)
    ax.axhline(0.0, color="0.6", lw=0.5)
    ax.set_xlim(0, 360)
    ax.set_xlabel("azimuth xi (deg)")
    ax.set_ylabel("out-of-plane error (mm)")
    ax.set_title(f"distance from the circle plane (max |.| "
                 f"{1000 * float(np.max(np.abs(err['out_of_plane_m']))):.3g} mm)")
    ax.grid(True, lw=0.3)
    return fig
