"""A flight log segment in memory, :class:`FlightLog`, and its one-line summary."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._schema import OPTIONAL_COLUMNS


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class FlightLog:
    """One gap-free segment of a flight log: pose, commanded thrusts, on-board sensors.

    What :func:`read_log` returns per segment (and :func:`log_from_arrays` builds, e.g.
    :func:`~gainsched.sim.loop.log_from_result` from a simulation). Frames and units of
    docs/conventions.md: inertial frame at the tether anchor, z up, SI units. The arrays
    are read-only; N is the number of samples (``len(log)``).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    p_I : ndarray, shape (N, 3)
        COG position (x, y, z) in the inertial frame, m.
    q : ndarray, shape (N, 4)
        Attitude quaternion (w, x, y, z), Hamilton, body -> inertial; unit norm and
        sign-continuous (consecutive samples have a non-negative dot product).
    T_cmd : ndarray, shape (N, 4)
        Commanded motor thrusts T1..T4, N, each held over the interval before its sample.
    optional : dict of str to ndarray
        The known optional columns present, by name: ``omega_B`` shape (N, 3), the gyro
        (p, q, r) in the body frame, rad/s; ``f_B`` shape (N, 3), the accelerometer's
        specific force (ax, ay, az) at the COG in the body frame, m/s^2; ``tension``
        shape (N,), the tether load cell, N; ``vbat`` shape (N,), the battery voltage, V;
        ``xi_ref`` shape (N,), the reference azimuth in the circle frame, rad;
        ``xi_dot_ref`` shape (N,), its rate, rad/s. May hold NaN (a missing sample).
    extra : dict of str to ndarray
        Unknown columns by their name, each shape (N,) float (kept; the analysis ignores
        them).
    meta : dict of str to str
        The metadata as strings: ``schema``, ``alpha_c_deg`` and ``gamma_c_deg`` (the
        commanded circle plane, deg) and any other key (``flight_id``, ``vehicle``,
        ``notes``, ...).
    source : str
        The file the log came from (or the ``source`` of :func:`log_from_arrays`).
    segment : int
        Index of this segment among the pieces the file was split into at gaps (0-based;
        dropped short pieces keep their index).
    n_segments : int
        How many pieces the file was split into (dropped ones included).
    gaps : tuple of (float, float)
        Every gap of the source file as ``(t_before, t_after)``, s.
    rows : ndarray of int64, shape (N,), or None
        Where each sample is in the file, 1-based (see ``row_label``).
    row_label : str
        ``"line"`` (``rows`` are CSV line numbers) or ``"sample"`` (HDF5 or arrays:
        sample indices).
    alpha_c, gamma_c : float
        Properties: the commanded circle tilt alpha_C and heading gamma_C of the metadata,
        rad.
    duration : float
        Property: time from the first to the last sample, s.
    dt_median : float
        Property: the median sample interval, s (nan with fewer than two samples).

    Examples
    --------
    >>> log = gs.read_log("examples/flights/tilt20-v8.csv")[0]
    >>> round(float(np.rad2deg(log.alpha_c)), 6), log.p_I.shape, log.T_cmd.shape
    (20.0, (551, 3), (551, 4))
    >>> log.where(0), log.columns()["T1"].shape  # where sample 0 is in the file
    ('line 7', (551,))
    """

    t: np.ndarray
    p_I: np.ndarray
    q: np.ndarray
    T_cmd: np.ndarray
    optional: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, str] = field(default_factory=dict)
    source: str = ""
    segment: int = 0
    n_segments: int = 1
    gaps: tuple[tuple[float, float], ...] = ()
    rows: np.ndarray | None = None
    row_label: str = "sample"

    @property
    def alpha_c(self) -> float:
        """Commanded circle tilt alpha_C, rad."""
        return math.radians(float(self.meta["alpha_c_deg"]))

    @property
    def gamma_c(self) -> float:
        """Commanded circle heading gamma_C, rad."""
        return math.radians(float(self.meta["gamma_c_deg"]))

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    @property
    def dt_median(self) -> float:
        """Median sample interval, s (nan with fewer than two samples)."""
        return float(np.median(np.diff(self.t))) if len(self) > 1 else math.nan

    def where(self, i: int) -> str:
        """``"line 17"`` / ``"sample 17"``: the file position of sample ``i`` (0-based)."""
        row = int(self.rows[i]) if self.rows is not None else i + 1
        return f"{self.row_label} {row}"

    def columns(self) -> dict[str, np.ndarray]:
        """All columns by their file name, in the canonical file order."""
        cols = {"t": self.t}
        for j, n in enumerate("xyz"):
            cols[n] = self.p_I[:, j]
        for j, n in enumerate(("qw", "qx", "qy", "qz")):
            cols[n] = self.q[:, j]
        for j in range(4):
            cols[f"T{j + 1}"] = self.T_cmd[:, j]
        for key, names in OPTIONAL_COLUMNS.items():
            if key in self.optional:
                arr = self.optional[key]
                if len(names) == 1:
                    cols[names[0]] = arr
                else:
                    for j, n in enumerate(names):
                        cols[n] = arr[:, j]
        for name in sorted(self.extra):
            cols[name] = self.extra[name]
        return cols


def _make(arrays, optional, extra, meta, source, sl, **kw) -> FlightLog:
    def cut(a):
        return _readonly(np.array(a[sl], dtype=float))

    return FlightLog(
        t=cut(arrays["t"]),
        p_I=cut(arrays["p_I"]),
        q=cut(arrays["q"]),
        T_cmd=cut(arrays["T_cmd"]),
        optional={k: cut(v) for k, v in optional.items()},
        extra={k: cut(v) for k, v in extra.items()},
        meta=dict(meta),
        source=str(source),
        **kw,
    )


def describe(log) -> str:
    """One-line summary of a log segment or a list of segments (as :func:`read_log` returns)."""
    logs = [log] if isinstance(log, FlightLog) else list(log)
    if not logs:
        return "empty log"
    first = logs[0]
    name = first.meta.get("flight_id") or Path(first.source).name or "log"
    samples = sum(len(lg) for lg in logs)
    duration = sum(lg.duration for lg in logs)
    dts = np.concatenate([np.diff(lg.t) for lg in logs])
    rate = 1.0 / float(np.median(dts)) if dts.size else math.nan
    if isinstance(log, FlightLog):
        seg = f"segment {first.segment + 1} of {first.n_segments}"
    else:
        seg = f"{len(logs)} of {first.n_segments} segment{'s' * (first.n_segments != 1)} kept"
    ngaps = len(first.gaps)
    return (
        f"{name}: {duration:.3f} s, {rate:.1f} Hz, {samples} samples, {seg}, "
        f"{ngaps} gap{'s' * (ngaps != 1)}, tilt {float(first.meta['alpha_c_deg']):g} deg"
    )
