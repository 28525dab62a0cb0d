"""The axes an automatic grid build chose, what they met and what they cost
(:class:`GridChoice`, returned by :func:`gainsched.schedule.refine.refine_grid`), and
the lines ``build``, ``inspect`` and ``check`` print of it (docs/grid.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .grid import GridResult

__all__ = ["GridChoice", "grid_auto_lines"]


@dataclass(frozen=True)
class GridChoice:
    """The axes a build chose and what they cost (:func:`refine_grid`).

    Attributes
    ----------
    config : Config
        The config with the chosen breakpoints as lists (its text keeps the ranges as
        comments): the table's config.
    grid : GridResult
        The grid solved on them.
    bound : float
        ``grid.max_interpolation_error``, a fraction.
    speeds_spec, tilts_spec, azimuth_spec : str or None
        The ranges as written (None: a list axis, or a fixed azimuth count, kept).
    azimuth_error : float
        The largest error of the interpolation along the azimuth alone at the cell
        centres (direct gains at the azimuth samples against the midpoints; a fraction).
    restarts : int
        Times the azimuth count was doubled and the circles solved again.
    dropped : int
        Breakpoint circles solved at a smaller azimuth count, dropped at a restart.
    gain_error, thrust_error, roll_error : float
        The largest relative errors at the cell midpoints (fractions).
    worst_rho : float
        The largest closed-loop spectral radius along a midpoint circle with
        interpolated gains.
    worst_cell : tuple
        ``(v_lo, v_hi, a_lo, a_hi)`` (m/s, deg) of the largest error.
    cells, skipped : int
        Cells certified; cells skipped (an infeasible corner or centre).
    rounds : int
        Refinement rounds.
    circles : int
        Breakpoint circles solved, each once (the chosen grid's).
    reused : int
        Breakpoint circles a round took from the earlier rounds instead of solving
        them again (the reuse counter).
    centres, centres_final : int
        Centre circles solved (the certificate); of them, the chosen grid's usable
        cells (the others belong to cells split later).
    source_sha256 : str
        SHA-256 of the config the build was given (with its ranges): the table's
        ``config_sha256`` is the chosen config's, so this says which config the user
        built it from (:meth:`~gainsched.schedule.tables.Table.built_from`).
    """

    config: object
    grid: GridResult
    bound: float
    speeds_spec: str | None
    tilts_spec: str | None
    azimuth_spec: str | None
    azimuth_error: float
    restarts: int
    dropped: int
    gain_error: float
    thrust_error: float
    roll_error: float
    worst_rho: float
    worst_cell: tuple
    cells: int
    skipped: int
    rounds: int
    circles: int
    reused: int
    centres: int
    centres_final: int
    source_sha256: str = ""

    @property
    def max_error(self) -> float:
        """The largest of the gain, thrust and roll errors (a fraction)."""
        return max(self.gain_error, self.thrust_error, self.roll_error)

    def record(self) -> dict:
        """What the table records of the choice (JSON-able, ``grid_auto`` in the table)."""
        g = self.config.grid
        return {
            "bound": self.bound,
            "speeds": self.speeds_spec,
            "tilts_deg": self.tilts_spec,
            "azimuth_samples_range": self.azimuth_spec,
            "azimuth_error": self.azimuth_error,
            "restarts": self.restarts,
            "dropped": self.dropped,
            "speed_count": int(g.speeds.size),
            "tilt_count": int(g.tilts.size),
            "azimuth_samples": int(g.azimuth_samples),
            "gain_error": self.gain_error,
            "thrust_error": self.thrust_error,
            "roll_error": self.roll_error,
            "worst_rho": self.worst_rho,
            "worst_cell": list(self.worst_cell),
            "cells": self.cells,
            "skipped": self.skipped,
            "rounds": self.rounds,
            "circles": self.circles,
            "reused": self.reused,
            "centres": self.centres,
            "centres_final": self.centres_final,
            "source_config_sha256": self.source_sha256,
        }

    def lines(self) -> list[str]:
        """What ``gainsched build`` prints of the choice: the grid, then the errors met
        and the cost as :func:`grid_auto_lines` renders the record."""
        g = self.config.grid
        tilts = np.rad2deg(g.tilts)

        def source(spec, fixed="as listed"):
            return f"chosen from {spec}" if spec else fixed

        return [
            f"grid chosen for {100 * self.bound:g} %: {g.speeds.size} speeds x {tilts.size} "
            f"tilts = {g.speeds.size * tilts.size} circles, {g.azimuth_samples} azimuth "
            f"samples ({source(self.azimuth_spec, 'as given')}; {self.rounds} rounds)",
            f"  speeds (m/s, {source(self.speeds_spec)}): "
            + ", ".join(f"{v:g}" for v in g.speeds),
            f"  tilts (deg, {source(self.tilts_spec)}): " + ", ".join(f"{a:g}" for a in tilts),
            *grid_auto_lines(self.record())[1:],
        ]


def grid_auto_lines(record: dict) -> list[str]:
    """A table's ``grid_auto`` record (:meth:`GridChoice.record`) as ``inspect`` and
    ``check`` print it (``build`` prints all but the first line): the ranges, the errors
    met at the cell midpoints, the cost."""
    r = record
    worst = max(r["gain_error"], r["thrust_error"], r["roll_error"])
    v_lo, v_hi, a_lo, a_hi = r["worst_cell"]
    return [
        f"grid chosen by the build for {100 * r['bound']:g}% (docs/grid.md): speeds "
        f"{r['speeds'] or 'as listed'}, tilts {r['tilts_deg'] or 'as listed'}, azimuth "
        f"samples {r['azimuth_samples_range'] or 'as given'}",
        f"  at {r['cells']} cell midpoints ({r['skipped']} skipped as infeasible): max "
        f"error {100 * worst:.2f} % (gains {100 * r['gain_error']:.2f}, thrusts "
        f"{100 * r['thrust_error']:.2f}, roll {100 * r['roll_error']:.2f}) in the cell "
        f"{v_lo:g}-{v_hi:g} m/s x {a_lo:g}-{a_hi:g} deg; along the azimuth alone "
        f"{100 * r['azimuth_error']:.2f} %; worst midpoint closed loop {r['worst_rho']:.5f}",
        f"  cost: {r['circles'] + r['centres'] + r['dropped']} circles solved = "
        f"{r['circles']} breakpoints, each once ({r['reused']} reused by later rounds) + "
        f"{r['centres']} cell centres ({r['centres_final']} certify the chosen grid)"
        + (f" + {r['dropped']} at a smaller azimuth count ({r['restarts']} restarts)"
           if r["dropped"] else ""),
    ]
