"""Two clocks made one: the offset and drift between a motion-capture recording and a
flight controller's log, estimated from signals both hold.

A lab records the pose on the motion-capture computer (a ROS 2 bag stamped in Unix time)
and the gyro, the accelerometer and the motor commands on the flight controller (a ULog
stamped from boot). Nothing in either file says how the clocks relate. Both hold the
same motion, seen twice:

- **body rate**: the gyro's ``|omega|`` against the rate of the pose's attitude (the
  rotation between attitudes 20 ms apart); magnitudes, so that the two files' frames
  (NED/FRD, ENU/FLU, a marker frame) do not matter;
- **specific force**: the accelerometer's ``|f|`` against ``|a - g|`` of the pose's
  positions (second differences over 40 ms), or, without an accelerometer, the sum of
  the motor commands (any monotonic map of the thrust correlates the same).

Each pair is averaged over 10 ms bins on each file's own clock (centred: the integral
of the samples' interpolant, so that 1 kHz and 100 Hz bin alike), high-passed (a moving
mean over 2 s removed: the steady circle says nothing of time) and normalised; their
cross-correlation over every lag the two spans allow (FFT) gives the offset where it
peaks (refined to a fraction of a bin by a parabola). The match must be clear: its
normalised correlation at least :data:`MIN_MATCH`, and every other lag more than
0.5 s away at most :data:`MAX_RUNNER_UP` of it (a periodic motion, or a recording of
another day, is refused, never guessed). Then the overlap is cut into windows
(:data:`WINDOWS`), the offset refined in each within +-0.2 s of the whole's, and a
line ``offset + drift (t - t_ref)`` fitted to them by least squares: its standard
errors are the uncertainty reported (the scatter of the windows about the line), and the
drift the rate difference of the two crystals (tens of ppm are usual).

Why by hand: scipy gives the correlation (``scipy.signal.correlate``) and the fit
(``numpy.polyfit``); what to correlate, the acceptance of a match and its uncertainty
are this problem's (the tools of the field, PlotJuggler and the PX4 log tools, leave the
offset to the user).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError

__all__ = ["BIN_S", "MIN_MATCH", "MAX_RUNNER_UP", "WINDOWS", "MIN_WINDOWS", "MIN_OVERLAP_S",
           "MIN_COVER", "ClockFit",
           "rate_magnitude", "specific_force_magnitude", "align_clocks"]

#: bin of the resampled signals, s
BIN_S = 0.01
#: the moving mean removed before correlating, s
HIGHPASS_S = 2.0
#: least normalised correlation of an accepted match (the same flight with motion-capture
#: and IMU noise: 0.8 and more; another flight's motion: 0.3 at the best offset)
MIN_MATCH = 0.5
#: most the best correlation more than 0.5 s from the match may reach, as a share of it
MAX_RUNNER_UP = 0.8
#: windows the overlap is cut into for the offset's line
WINDOWS = 12
#: a drift is kept when it is at least this many standard errors from 0 (else the clocks'
#: rates do not differ measurably over the day: the offset alone, its mean over the
#: windows)
DRIFT_SIGNIFICANCE = 3.0
#: least overlap of the two files, s
MIN_OVERLAP_S = 10.0
#: least share of the shorter file the other must cover at a candidate offset (a lab
#: records both files over the same flights; a few seconds of overlap match anything)
MIN_COVER = 0.5
#: fewest windows whose motion must match the other file's
MIN_WINDOWS = 3
#: half width of the search about the whole's offset in each window, s
_LOCAL_S = 0.2
#: lags this close to the match are its own peak, s
_PEAK_S = 0.5
#: the windows (s) of the pose's rate and acceleration
RATE_WINDOW_S = 0.02
ACCEL_WINDOW_S = 0.04


@dataclass(frozen=True)
class ClockFit:
    """How the pose file's clock maps onto the flight controller's.

    ``t_fc = t_pose + offset_s + drift (t_pose - t_ref_s)``.

    Attributes
    ----------
    offset_s, offset_sigma_s : float
        The offset at ``t_ref_s`` and its standard error, s.
    drift, drift_sigma : float
        The rate difference of the clocks, s/s, and its standard error (0 and NaN when
        only 3 windows matched: not estimated; 0 and the standard error when it is
        within :data:`DRIFT_SIGNIFICANCE` of them: not seen over the day).
    t_ref_s : float
        The pose-clock time the offset is given at (the middle of the windows), s.
    correlation, runner_up : float
        The match's normalised correlation, and the best more than 0.5 s from it.
    overlap_s : float
        The span both files cover once aligned, s.
    windows : int
        The windows whose offsets made the line.
    signals : tuple of str
        The pairs correlated (``"body rate"``, ``"specific force"``, ``"thrust"``).
    """

    offset_s: float
    offset_sigma_s: float
    drift: float
    drift_sigma: float
    t_ref_s: float
    correlation: float
    runner_up: float
    overlap_s: float
    windows: int
    signals: tuple[str, ...]

    def fc_from_pose(self, t_pose):
        """Pose-clock times (s) on the flight controller's clock, s."""
        t = np.asarray(t_pose, dtype=np.float64)
        return t + self.offset_s + self.drift * (t - self.t_ref_s)

    def line(self) -> str:
        """What ``convert`` prints about the clocks."""
        sig = f" +- {1e3 * self.offset_sigma_s:.2g} ms"
        drift = ("drift not estimated" if not math.isfinite(self.drift_sigma) else
                 f"no drift seen (+- {1e6 * self.drift_sigma:.2g} ppm)" if self.drift == 0
                 else f"drift {1e6 * self.drift:+.3g} +- {1e6 * self.drift_sigma:.2g} ppm")
        sign = "-" if self.offset_s < 0 else "+"
        return (f"clocks: pose time {sign} {abs(self.offset_s):.6f} s{sig} (1 sigma), "
                f"{drift}, from "
                f"{' and '.join(self.signals)} (correlation {self.correlation:.2f}, next "
                f"best {self.runner_up:.2f}; {self.windows} windows of {self.overlap_s:.0f} "
                "s in common)")


# --------------------------------------------------------------------------- signals


def rate_magnitude(t, q) -> tuple[np.ndarray, np.ndarray]:
    """``(t_mid, |omega|)``: the rate (rad/s) of the attitudes ``q`` (n, 4), scalar
    first, each over the rotation to the sample about :data:`RATE_WINDOW_S` later."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    m = _lag(t, RATE_WINDOW_S)
    if t.size <= m:
        return np.zeros(0), np.zeros(0)
    a, b = q[:-m], q[m:]
    dot = np.abs(np.einsum("ij,ij->i", a, b)) / (
        np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    angle = 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
    return 0.5 * (t[:-m] + t[m:]), angle / (t[m:] - t[:-m])


def specific_force_magnitude(t, p, g_world) -> tuple[np.ndarray, np.ndarray]:
    """``(t, |a - g|)``: the specific force (m/s^2) of the positions ``p`` (n, 3) m in a
    world frame whose gravity vector is ``g_world`` (3,), from second differences over
    about :data:`ACCEL_WINDOW_S`."""
    t = np.asarray(t, float)
    p = np.asarray(p, float)
    m = _lag(t, ACCEL_WINDOW_S / 2)
    if t.size <= 2 * m:
        return np.zeros(0), np.zeros(0)
    t0, t1, t2 = t[:-2 * m], t[m:-m], t[2 * m:]
    v1 = (p[m:-m] - p[:-2 * m]) / (t1 - t0)[:, None]
    v2 = (p[2 * m:] - p[m:-m]) / (t2 - t1)[:, None]
    a = 2.0 * (v2 - v1) / (t2 - t0)[:, None]
    return t1, np.linalg.norm(a - np.asarray(g_world, float), axis=1)


def _lag(t: np.ndarray, seconds: float) -> int:
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    return max(1, int(round(seconds / dt)))


def _binned(t: np.ndarray, x: np.ndarray, t0: float, n: int) -> np.ndarray:
    """The means of ``x`` over the bins centred on ``t0 + k BIN_S``, k < n: the integral
    of its linear interpolant over each bin (exactly centred whatever the sample rate,
    so that a 1 kHz and a 100 Hz signal of the same motion bin alike)."""
    ok = np.isfinite(x)
    t, x = t[ok], x[ok]
    if t.size < 2:
        return np.zeros(n)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))])
    centre = t0 + BIN_S * np.arange(n)
    hi = np.interp(centre + 0.5 * BIN_S, t, integral)
    lo = np.interp(centre - 0.5 * BIN_S, t, integral)
    return (hi - lo) / BIN_S


def _prepared(t, x, t0: float, n: int) -> np.ndarray:
    """Binned, high-passed and normalised (unit RMS)."""
    from scipy.ndimage import uniform_filter1d

    y = _binned(np.asarray(t, float), np.asarray(x, float), t0, n)
    y = y - uniform_filter1d(y, max(1, int(round(HIGHPASS_S / BIN_S))), mode="nearest")
    rms = float(np.sqrt(np.mean(y**2)))
    return y / rms if rms > 0 else y


# --------------------------------------------------------------------------- alignment


def _correlation(a: np.ndarray, b: np.ndarray, min_count: int):
    """Normalised cross-correlation of unit-RMS ``a`` and ``b`` at every lag with at
    least ``min_count`` samples in common: ``(lags, c)``, ``a[n + lag] ~ b[n]``."""
    from scipy.signal import correlate, correlation_lags

    num = correlate(a, b, mode="full", method="fft")
    cnt = correlate(np.ones_like(a), np.ones_like(b), mode="full", method="fft")
    lags = correlation_lags(a.size, b.size, mode="full")
    keep = cnt > min_count - 0.5
    return lags[keep], num[keep] / np.maximum(cnt[keep], 1.0)


def _peak(lags: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """The lag of the peak, refined by a parabola through it and its neighbours, and the
    peak's value."""
    i = int(np.argmax(c))
    if 0 < i < c.size - 1:
        y0, y1, y2 = c[i - 1], c[i], c[i + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        return float(lags[i] + frac), float(c[i])
    return float(lags[i]), float(c[i])


def align_clocks(fc_signals: dict, pose_signals: dict, *, fc_name="flight controller",
                 pose_name="pose") -> ClockFit:
    """The offset and drift that put the pose file's clock on the flight controller's.

    Parameters
    ----------
    fc_signals, pose_signals : dict
        Per pair name (``"body rate"``, ``"specific force"``, ``"thrust"``) the signal
        ``(t, x)`` of each file, t in s on the file's own clock; the pairs both hold are
        correlated.
    fc_name, pose_name : str
        The files, for the refusals.

    Returns
    -------
    ClockFit

    Raises
    ------
    InputError
        No pair both hold, the files share less than :data:`MIN_OVERLAP_S` s at any lag,
        no clear match (correlation below :data:`MIN_MATCH`: not the same flight), or an
        ambiguous one (another lag within :data:`MAX_RUNNER_UP` of it).
    """
    names = tuple(k for k in fc_signals if k in pose_signals)
    if not names:
        raise InputError(pose_name, "", f"no signal to align its clock with {fc_name} (the "
                         "pose gives body rates and accelerations; the flight controller's "
                         "map names no gyro, accelerometer or motors)")
    fa0 = min(float(fc_signals[k][0][0]) for k in names)
    fa1 = max(float(fc_signals[k][0][-1]) for k in names)
    pb0 = min(float(pose_signals[k][0][0]) for k in names)
    pb1 = max(float(pose_signals[k][0][-1]) for k in names)
    na, nb = int((fa1 - fa0) / BIN_S) + 1, int((pb1 - pb0) / BIN_S) + 1
    # the shorter file at least half covered: a short overlap matches by chance
    min_count = max(int(MIN_OVERLAP_S / BIN_S), int(MIN_COVER * min(na, nb)))
    if min(na, nb) * BIN_S < MIN_OVERLAP_S:
        raise InputError(pose_name, "", f"{min(na, nb) * BIN_S:.3g} s of signal: too short "
                         f"to align the clocks (at least {MIN_OVERLAP_S:g} s in common)")
    A = {k: _prepared(*fc_signals[k], fa0, na) for k in names}
    B = {k: _prepared(*pose_signals[k], pb0, nb) for k in names}
    total = None
    for k in names:
        lags, c = _correlation(A[k], B[k], min_count)
        total = c if total is None else total + c
    c = total / len(names)
    lag, best = _peak(lags, c)
    far = np.abs(lags - lag) * BIN_S > _PEAK_S
    runner = float(c[far].max()) if far.any() else 0.0
    if best < MIN_MATCH:
        raise InputError(pose_name, "", f"its motion does not match {fc_name}'s at any clock "
                         f"offset (best correlation {best:.2f}; the same flight gives "
                         f"{MIN_MATCH:g} and more): a recording of another flight or day?")
    if runner > MAX_RUNNER_UP * best:
        raise InputError(pose_name, "", f"the clock offset to {fc_name} is ambiguous: "
                         f"{best:.2f} at {fa0 - pb0 + lag * BIN_S:.3f} s, {runner:.2f} at "
                         "another offset more than 0.5 s away (a motion that repeats, or "
                         "another flight): set time.pose_offset_s in the pose's map")
    offset0 = fa0 - pb0 + lag * BIN_S
    return _fit_line(A, B, names, lag, offset0, pb0, best, runner, (fa0, fa1, pb0, pb1),
                     fc_name, pose_name)


def _fit_line(A, B, names, lag, offset0, pb0, best, runner, spans, fc_name: str,
              pose_name: str) -> ClockFit:
    """The offset refined per window of the overlap and the line through them."""
    fa0, fa1, _, pb1 = spans
    lo = max(pb0, fa0 - offset0)  # the overlap on the pose clock
    hi = min(pb1, fa1 - offset0)
    if hi - lo < MIN_OVERLAP_S:
        raise InputError(pose_name, "", f"the two files share {max(hi - lo, 0):.3g} s once "
                         f"aligned: they do not overlap (at least {MIN_OVERLAP_S:g} s)")
    edges = np.linspace(lo, hi, WINDOWS + 1)
    r = int(round(_LOCAL_S / BIN_S))
    t_mid, offs = [], []
    for w0, w1 in zip(edges[:-1], edges[1:], strict=True):
        j0, j1 = int((w0 - pb0) / BIN_S), int((w1 - pb0) / BIN_S)
        base = j0 + int(round(lag))
        cs = np.zeros(2 * r + 1)
        for k in names:
            b = B[k][j0:j1]
            for i, d in enumerate(range(-r, r + 1)):
                s0 = base + d
                if s0 < 0 or s0 + b.size > A[k].size or b.size == 0:
                    cs[i] = -np.inf
                    continue
                a = A[k][s0:s0 + b.size]
                den = math.sqrt(float(a @ a) * float(b @ b))
                cs[i] += float(a @ b) / den if den > 0 else 0.0
        cs /= len(names)
        if not np.isfinite(cs).all() or cs.max() < MIN_MATCH:
            continue  # a window without motion (ground time) or at the edge
        d, _ = _peak(np.arange(-r, r + 1, dtype=float), cs)
        t_mid.append(0.5 * (w0 + w1))
        offs.append(offset0 + (int(round(lag)) - lag + d) * BIN_S)
    t_mid, offs = np.asarray(t_mid), np.asarray(offs)
    n = t_mid.size
    if n < MIN_WINDOWS:
        raise InputError(pose_name, "", f"its motion matches {fc_name}'s in {n} of {WINDOWS} "
                         f"stretches of the overlap only (at least {MIN_WINDOWS}): not the "
                         "same flight, or too little motion to align the clocks; set "
                         "time.pose_offset_s in the pose's map")
    t_ref = float(t_mid.mean())
    offset, so = float(offs.mean()), float(offs.std(ddof=1) / math.sqrt(n))
    drift, sd = 0.0, math.nan
    if n >= 4:  # the line; its drift kept when it stands out of its standard error
        X = np.stack([np.ones(n), t_mid - t_ref], -1)
        coef, *_ = np.linalg.lstsq(X, offs, rcond=None)
        res = offs - X @ coef
        cov = float(res @ res) / (n - 2) * np.linalg.inv(X.T @ X)
        sd = math.sqrt(cov[1, 1])
        if abs(coef[1]) >= DRIFT_SIGNIFICANCE * sd:
            offset, drift, so = float(coef[0]), float(coef[1]), math.sqrt(cov[0, 0])
    return ClockFit(offset, so, drift, sd, t_ref, best, runner, float(hi - lo), int(n), names)
