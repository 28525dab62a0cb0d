"""The result of a comparison, :class:`Comparison`: what
:func:`~gainsched.analysis.compare.compare` computes, its normalised RMS and its JSON.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...config import Config
from ._axes import _SENSOR_OF, UNITS


@dataclass(frozen=True, eq=False)
class Comparison:
    """The model against flight logs: residuals, statistics per axis, noise floors, where it fails.

    Everything :func:`compare` computes (``gainsched compare``; docs/model-vs-measurement.md).
    The residual axes, in the order of :data:`AXES` and with the units of :data:`UNITS`:
    tangential, normal, radial (m/s^2; radial only when every segment has a load cell),
    roll, pitch, yaw (rad/s^2) and stretch (m). ``cmp.axes`` lists those present,
    ``cmp.normalized_rms()`` is ``sqrt(mean over axes of (RMS / noise floor)^2)`` (1:
    the residual is measurement noise), ``cmp.to_json()`` is the report's JSON and
    ``cmp.sensor_lines()`` says what the on-board sensors saved.

    Attributes
    ----------
    config : Config
        The model that was compared.
    measured : list of Measured
        Every log segment in reduced coordinates, differentiated
        (:class:`~gainsched.analysis.compare.Measured`), in the order of ``segs``.
    residuals : list of Residual
        Per segment, the measured, predicted and residual time series of each axis on
        the core samples (half a differentiation window dropped at each end)
        (:class:`~gainsched.analysis.compare.Residual`).
    stats : dict of str to AxisStats
        By axis: RMS, bias, fit %, noise floor, whiteness and input cross-correlation of
        the residual pooled over the segments, in the axis unit
        (:class:`~gainsched.analysis.compare.AxisStats`; ``rms_over_noise`` is RMS over
        the noise floor).
    noise : dict of str to float
        By axis: the noise floor, the RMS residual the measurement noise alone produces,
        in the axis unit.
    where : dict
        Where the model fails (:func:`where_it_fails`): ``"sentence"`` (str, the worst
        regime in words), ``"worst"`` (dict: the axis and, when binned structure names
        it, the variable and its bin), ``"rms_over_noise"`` (axis to float) and
        ``"tables"`` (the residual binned against airspeed, tilt, azimuth, tension,
        thrust and time).
    notes : list of str
        What reading the logs reported: gaps and dropped short segments.
    segs : list of FlightLog
        The log segments compared.
    tracking : list of dict
        Along-track tracking of each segment with a reference azimuth
        (:func:`tracking_summary`): ``segment``, ``rms_along_track_m``,
        ``max_along_track_m`` (m), ``final_azimuth_error_rad`` (rad), ``lap_slips``.
    structure : list of Finding
        Significant binned structure of the residual (averaged over revolutions, in
        azimuth, airspeed, thrust or time bins), strongest first
        (:func:`gainsched.analysis.structure.findings`; ``f.sentence()`` says it).
    structure_tables : dict of str to dict
        Its tables, ``{variable: {axis: BinnedMean}}``.
    pose_noise : dict of str to float
        For the axes an on-board sensor measured (rotational: the gyro; translational:
        the accelerometer), the noise floor from the pose alone (:func:`noise_floor`), in
        the axis unit: what the sensor saved against ``noise``.

    Examples
    --------
    >>> cfg = gs.load_config("configs/paper.toml")
    >>> cmp = gs.compare(cfg, ["examples/flights/v9.csv", "examples/flights/v15.csv"])
    >>> cmp.axes
    ('tangential', 'normal', 'radial', 'roll', 'pitch', 'yaw', 'stretch')
    >>> [s.white for s in cmp.stats.values()]  # whiteness of the residual, per axis
    [False, False, True, False, True, True, True]
    >>> [t["segment"] for t in cmp.tracking], len(cmp.residuals), cmp.notes
    (['sim-v9', 'sim-v15'], 2, [])
    """

    config: Config
    measured: list
    residuals: list
    stats: dict
    noise: dict
    where: dict
    notes: list
    segs: list = field(default_factory=list)
    tracking: list = field(default_factory=list)
    #: significant binned structure (:func:`gainsched.analysis.structure.findings`),
    #: strongest first, and its tables ``{variable: {axis: BinnedMean}}``
    structure: list = field(default_factory=list)
    structure_tables: dict = field(default_factory=dict)
    #: the noise floors from the pose alone of the axes an on-board sensor measured
    #: (:func:`noise_floor`; rotational: gyro, translational: accelerometer): what the
    #: sensors saved
    pose_noise: dict = field(default_factory=dict)


    def __repr__(self) -> str:
        """One line: the config, the segments and the normalised RMS (1: measurement noise)."""
        return (f"Comparison({self.config.name!r}, {len(self.measured)} segments, "
                f"normalised RMS {self.normalized_rms():.3g})")
    def sensor_lines(self) -> list[str]:
        """One sentence per axis measured with an on-board sensor: its noise floor with
        the sensor against the pose's alone."""
        return [f"{a}: noise floor {self.noise[a]:.3g} {UNITS[a]} with the "
                f"{_SENSOR_OF.get(a, 'gyro')}, {p:.3g} from the pose alone "
                f"({self.noise[a] / p - 1:+.0%})"
                for a, p in self.pose_noise.items() if a in self.noise and p > 0]

    def _sensor_json(self, axes) -> dict:
        used = {a: p for a, p in self.pose_noise.items() if a in axes}
        return {"used": bool(used), "pose_noise_floor": used,
                "noise_floor": {a: self.noise[a] for a in used}}

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(self.stats)

    def normalized_rms(self, axes=None) -> float:
        """sqrt(mean over axes of (RMS / noise floor)^2): 1 for a residual of pure noise."""
        axes = axes or self.axes
        return float(np.sqrt(np.mean([(self.stats[a].rms / self.noise[a]) ** 2 for a in axes])))

    def to_json(self) -> dict:
        return {
            "config": {"name": self.config.name, "source": self.config.source,
                       "sha256": self.config.sha256,
                       "effects": {e.name: e.param_dict() for e in self.config.effects},
                       "analysis": {"savgol_window_s": self.config.analysis.savgol_window_s,
                                    "savgol_order": self.config.analysis.savgol_order,
                                    "latency_s": self.config.analysis.latency_s}},
            "segments": [{"name": r.name, "source": r.source, "samples": len(r),
                          "t_start": float(r.t[0]), "t_end": float(r.t[-1]),
                          "tension": r.tension_source, "window_samples": r.window}
                         for r in self.residuals],
            "axes": {a: s.to_json() for a, s in self.stats.items()},
            "normalized_rms": self.normalized_rms(),
            "where_it_fails": {"sentence": self.where["sentence"], "worst": self.where["worst"],
                               "rms_over_noise": self.where["rms_over_noise"],
                               "tables": self.where["tables"]},
            "notes": self.notes,
            "tracking": self.tracking,
            "gyro": self._sensor_json(("roll", "pitch", "yaw")),
            "accelerometer": self._sensor_json(("tangential", "normal", "radial")),
            "structure": {"findings": [f.to_json() for f in self.structure],
                          "tables": {v: {a: bm.to_json() for a, bm in tab.items()}
                                     for v, tab in self.structure_tables.items()}},
        }
