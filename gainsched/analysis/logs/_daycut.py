"""A flight day cut into the flights the analysis can use: each steady circle with its
speed, tilt and heading, each manoeuvre with its start and end speeds; the ground, the
take-offs and landings, the pauses and the transitions dropped, each with its reason.

A lab's day is one long log: the vehicle on the ground, a take-off onto the tether's
sphere, circles at several speeds and tilts, speed changes between them, pauses, a
landing. The model describes the taut-tether circle (docs/model.md), so the analysis
takes what is one:

- **airborne on the sphere**: the commanded thrust holds at least a third of the
  weight, the tether is taut (the positions within :data:`SPHERE_TOL` of the tether's
  radius, ``tether.length + attachment_offset``) and the vehicle moves (speed above
  :data:`MIN_SPEED`); the rest is ``ground`` (thrust off), ``off the sphere``
  (take-off, landing, a slack tether) or ``hover`` (on the sphere, too slow to fly a
  circle);
- **steady**: the speed's rate of change, over :data:`SMOOTH_S`, below
  :data:`STEADY_ACCEL`; a steady run of at least :data:`MIN_CIRCLE_S` in one plane
  through the anchor (flat to :data:`PLANE_FLAT_TOL` of its spread, one normal from
  its first half to its second within :data:`PLANE_TURN_DEG`) is a ``circle``, with
  its median speed and the plane's tilt and heading;
- **manoeuvre**: an accelerating run (the speed changing monotonically) between two
  circles of one plane, with :data:`MANOEUVRE_MARGIN_S` of each on either side (taken
  from the circles: no sample is in two flights); one that does not join two circles
  of one plane is a ``transition``.

Each piece keeps its samples (no interpolation) and gets the plane it flew in its
metadata, so it is read, checked and analysed as a log of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ._checks import fitted_plane
from ._consistency import _plane_angles, _plane_normal

__all__ = ["SPHERE_TOL", "MIN_SPEED", "STEADY_ACCEL", "MIN_CIRCLE_S", "Piece", "DayCut",
           "cut_day"]

#: the positions on the tether's sphere: within this share of its radius
SPHERE_TOL = 0.05
#: slowest circle, m/s
MIN_SPEED = 1.0
#: least commanded thrust of a flight, as a share of the weight
MIN_THRUST = 1.0 / 3.0
#: smoothing of the speed and of its rate of change, s
SMOOTH_S = 0.5
#: a steady speed changes by less than this, m/s^2
STEADY_ACCEL = 0.5
#: shortest circle kept, s
MIN_CIRCLE_S = 3.0
#: shortest manoeuvre kept (its accelerating run), s
MIN_MANOEUVRE_S = 0.3
#: steady samples kept on either side of a manoeuvre, s
MANOEUVRE_MARGIN_S = 0.5
#: a dropped piece shorter than this, next to another dropped one, joins it, s
MERGE_S = 1.0
#: a circle's plane: out-of-plane spread at most this share of the in-plane one
PLANE_FLAT_TOL = 0.1
#: most a circle's plane may turn from its first half to its second, deg
PLANE_TURN_DEG = 5.0


@dataclass(frozen=True)
class Piece:
    """A stretch of the day.

    Attributes
    ----------
    kind : str
        ``"circle"``, ``"manoeuvre"`` (kept); ``"ground"``, ``"off the sphere"``,
        ``"hover"``, ``"transition"``, ``"short"`` (dropped).
    start, stop : int
        Its samples, ``[start, stop)``.
    t0, t1 : float
        Its first and last time, s.
    speed, speed_end : float
        Median speed (a circle; both equal), or the speeds at its start and end (a
        manoeuvre), m/s; NaN for a dropped piece.
    tilt_deg, heading_deg : float
        The plane it flew (``alpha_c``, ``gamma_c``), deg; NaN for a dropped piece.
    why : str
        Why it was dropped ("" when kept).
    """

    kind: str
    start: int
    stop: int
    t0: float
    t1: float
    speed: float = math.nan
    speed_end: float = math.nan
    tilt_deg: float = math.nan
    heading_deg: float = math.nan
    why: str = ""

    @property
    def kept(self) -> bool:
        return self.kind in ("circle", "manoeuvre")

    @property
    def name(self) -> str:
        """A short label: ``circle 6.0 m/s 20 deg``, ``manoeuvre 6.0->10.0 m/s``."""
        if self.kind == "circle":
            return f"circle {self.speed:.1f} m/s {self.tilt_deg:.0f} deg"
        if self.kind == "manoeuvre":
            return f"manoeuvre {self.speed:.1f}->{self.speed_end:.1f} m/s"
        return self.kind


@dataclass(frozen=True)
class DayCut:
    """The pieces of a day, in time order (:func:`cut_day`)."""

    pieces: tuple[Piece, ...]

    @property
    def kept(self) -> tuple[Piece, ...]:
        return tuple(p for p in self.pieces if p.kept)

    def lines(self) -> list[str]:
        """A table of the pieces: time, duration, what, and why a dropped one was."""
        out = [f"the day: {len(self.kept)} flights kept of {len(self.pieces)} pieces"]
        for p in self.pieces:
            what = p.name + (f", heading {p.heading_deg:.0f} deg" if p.kept and
                             p.tilt_deg > 0.5 else "")
            out.append(f"  {p.t0:9.2f}-{p.t1:9.2f} s  {p.t1 - p.t0:7.2f} s  "
                       f"{'kept' if p.kept else 'dropped'}  {what}"
                       + (f" ({p.why})" if p.why else ""))
        return out

    def to_json(self) -> dict:
        return {"pieces": [{"kind": p.kind, "kept": p.kept, "t0_s": p.t0, "t1_s": p.t1,
                            "samples": p.stop - p.start,
                            "speed_mps": None if math.isnan(p.speed) else p.speed,
                            "speed_end_mps": None if math.isnan(p.speed_end) else p.speed_end,
                            "tilt_deg": None if math.isnan(p.tilt_deg) else p.tilt_deg,
                            "heading_deg": None if math.isnan(p.heading_deg)
                            else p.heading_deg, "why": p.why} for p in self.pieces]}


def _smooth(t: np.ndarray, x: np.ndarray, seconds: float) -> np.ndarray:
    """A centred moving mean over about ``seconds`` (on the median sample interval)."""
    from scipy.ndimage import uniform_filter1d

    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    return uniform_filter1d(x, max(1, int(round(seconds / dt))), axis=0, mode="nearest")


def _plane(p: np.ndarray) -> tuple[float, float, bool]:
    """``(tilt, heading, ok)`` of the plane through the anchor the positions fly: ok when
    they are flat in it and its normal does not turn from the first half to the
    second."""
    n, s = fitted_plane(p)
    flat = s[2] <= PLANE_FLAT_TOL * s[1]
    half = p.shape[0] // 2
    turn = 0.0
    if half >= 10:
        n1, _ = fitted_plane(p[:half])
        n2, _ = fitted_plane(p[half:])
        turn = math.degrees(math.acos(min(1.0, abs(float(n1 @ n2)))))
    tilt, heading = _plane_angles(n)
    return tilt, heading, bool(flat and turn <= PLANE_TURN_DEG)


def cut_day(t, p_I, T_cmd, *, radius: float, weight: float) -> DayCut:
    """Cut a day's log into circles, manoeuvres and what is dropped (module docstring).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Time, s, increasing.
    p_I : ndarray, shape (N, 3)
        Positions from the anchor, m.
    T_cmd : ndarray, shape (N, 4)
        Commanded motor thrusts, N (NaN: not commanded).
    radius : float
        The tether's radius ``tether.length + attachment_offset``, m.
    weight : float
        The vehicle's weight ``m g``, N.

    Returns
    -------
    DayCut
    """
    t = np.asarray(t, float)
    p = np.asarray(p_I, float)
    thrust = np.nansum(np.asarray(T_cmd, float), axis=1)
    v = np.gradient(p, t, axis=0)
    speed = _smooth(t, np.linalg.norm(v, axis=1), SMOOTH_S)
    accel = _smooth(t, np.gradient(speed, t), SMOOTH_S)
    on_sphere = np.abs(np.linalg.norm(p, axis=1) - radius) <= SPHERE_TOL * radius
    powered = _smooth(t, thrust, SMOOTH_S) >= MIN_THRUST * weight
    flying = on_sphere & powered & (speed >= MIN_SPEED)
    label = np.where(~powered, 0, np.where(~on_sphere, 1, np.where(~flying, 2, 3)))
    pieces: list[Piece] = []
    for k, j in _change_points(label) if t.size else []:  # the day's runs of one label
        if label[k] == 3:
            pieces += _flying(t, p, speed, accel, k, j)
            continue
        kind = ("ground", "off the sphere", "hover")[label[k]]
        why = ("thrust below a third of the weight" if kind == "ground" else
               f"more than {100 * SPHERE_TOL:.0f} % off the tether's radius {radius:g} m "
               "(take-off, landing, slack)" if kind == "off the sphere" else
               f"slower than {MIN_SPEED:g} m/s")
        pieces.append(Piece(kind, k, j, float(t[k]), float(t[j - 1]), why=why))
    return DayCut(_merged(pieces))


def _merged(pieces: list[Piece]) -> tuple[Piece, ...]:
    """Dropped pieces shorter than :data:`MERGE_S` next to a dropped piece take the kind
    of their longer dropped neighbour (a take-off crosses the sphere's band several
    times), then runs of one kind are one piece."""
    kinds = [(q.kind, q.why) for q in pieces]

    def span(i):
        return pieces[i].t1 - pieces[i].t0

    for i, q in enumerate(pieces):
        if q.kept or span(i) >= MERGE_S:
            continue
        near = [j for j in (i - 1, i + 1) if 0 <= j < len(pieces) and not pieces[j].kept]
        if near:
            kinds[i] = kinds[max(near, key=span)]
    out: list[Piece] = []
    for q, (kind, why) in zip(pieces, kinds, strict=True):
        if out and not q.kept and not out[-1].kept and out[-1].kind == kind:
            last = out.pop()
            q = Piece(kind, last.start, q.stop, last.t0, q.t1, why=why)
        elif not q.kept:
            q = Piece(kind, q.start, q.stop, q.t0, q.t1, why=why)
        out.append(q)
    return tuple(out)


def _flying(t, p, speed, accel, a: int, b: int) -> list[Piece]:
    """The pieces of one airborne run ``[a, b)``: circles, manoeuvres, transitions."""
    steady = np.abs(accel[a:b]) < STEADY_ACCEL
    runs = [(a + i, a + j, bool(steady[i])) for i, j in _change_points(steady)]
    circles: dict[int, Piece] = {}
    out: list[Piece | None] = []
    for idx, (i, j, st) in enumerate(runs):
        if st and t[j - 1] - t[i] >= MIN_CIRCLE_S:
            tilt, heading, ok = _plane(p[i:j])
            if ok:
                v = float(np.median(speed[i:j]))
                circles[idx] = Piece("circle", i, j, float(t[i]), float(t[j - 1]), v, v,
                                     tilt, heading)
                out.append(circles[idx])
                continue
            out.append(Piece("transition", i, j, float(t[i]), float(t[j - 1]),
                             why="not in one plane through the anchor"))
            continue
        out.append(None)  # decided below, knowing its neighbours
    for idx, (i, j, st) in enumerate(runs):
        if out[idx] is not None:
            continue
        before, after = circles.get(idx - 1), circles.get(idx + 1)
        if st:
            why = f"steady for {t[j - 1] - t[i]:.2f} s, shorter than a circle ({MIN_CIRCLE_S:g} s)"
            out[idx] = Piece("short", i, j, float(t[i]), float(t[j - 1]), why=why)
            continue
        same = (before is not None and after is not None and
                _angle(before, after) <= PLANE_TURN_DEG)
        if not same or t[j - 1] - t[i] < MIN_MANOEUVRE_S:
            why = ("not between two circles of one plane" if not same else
                   f"shorter than {MIN_MANOEUVRE_S:g} s")
            out[idx] = Piece("transition", i, j, float(t[i]), float(t[j - 1]), why=why)
            continue
        m = int(round(MANOEUVRE_MARGIN_S / float(np.median(np.diff(t[i:j + 1])))))
        i0, j0 = max(before.start, i - m), min(after.stop, j + m)
        out[idx] = Piece("manoeuvre", i0, j0, float(t[i0]), float(t[j0 - 1]),
                         before.speed, after.speed, before.tilt_deg, before.heading_deg)
        # the circles give the manoeuvre their margins: no sample in two flights (a
        # held-out score would see it twice)
        out[idx - 1] = circles[idx - 1] = replace(out[idx - 1], stop=i0, t1=float(t[i0 - 1]))
        out[idx + 1] = circles[idx + 1] = replace(out[idx + 1], start=j0, t0=float(t[j0]))
    return [q for q in out if q is not None]


def _angle(a: Piece, b: Piece) -> float:
    """Angle between the planes of two pieces, deg."""
    na, nb = _plane_normal(a.tilt_deg, a.heading_deg), _plane_normal(b.tilt_deg, b.heading_deg)
    return math.degrees(math.acos(min(1.0, abs(float(na @ nb)))))


def _change_points(x: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of each run of equal values of ``x``."""
    edges = np.flatnonzero(np.diff(x.astype(np.int64))) + 1
    bounds = [0, *edges.tolist(), x.size]
    return list(zip(bounds[:-1], bounds[1:], strict=True))
