"""The first crossing of the unit circle by a family of periodic loops: the root search
of the stability margins (:mod:`gainsched.schedule.margins`, docs/margins.md).

A margin is the first parameter p (a factor on the commands, a delay) from the nominal
outward at which a Floquet multiplier of the loop reaches the unit circle. The loop is
known only through its multipliers at any p (one monodromy each), so the search is a
scan that brackets the first crossing and a refinement inside the bracket, for every
(loop, margin) pair of a batch at once. Why by hand: scipy's brentq solves one scalar
root at a time and knows nothing of brackets shared by a batch, of a cheaper surrogate,
or of the multiplier that crosses.
"""

from __future__ import annotations

import numpy as np

__all__ = ["first_crossings"]

#: refinement steps at most
_REFINE = 60

#: the scan's points, as fractions of the search range, evaluated in rounds from the
#: nominal outward (a margin whose crossing is bracketed stops scanning)
_SCAN = np.array([1, 2, 4, 8]) / 8.0
#: the scan around a guess of the crossing, as multiples of it, in rounds (then the
#: range's end): half of it, the first crossing's check, with two points at once at and
#: just above it, whose log rho (both on the crossing mode when unstable) gives the
#: secant its first step; then further above. On the paper grid's tilted circles 505
#: delayed loops against 599 with a round at 0.97 before the pair, the same margins to
#: the last bit
_AROUND = (np.array([0.5, 1.0, 1.005]), np.array([1.3]), np.array([1.6]), np.array([2.5]))
#: the real loop checks a bracket of this relative width around the surrogate's crossing
_CHECK = 1e-3
#: and widens it this many times (4x each) to find the crossing just outside it
_WIDEN = 3
#: "no crossing" on the surrogate stands where its log rho stayed below minus this
_SURROGATE_ERROR = 1e-3


class _Brackets:
    """The brackets ``[a, b]`` of flat (loop, margin) pairs: the loop is stable at a and
    not at b (b inf: no crossing found), with log rho at both."""

    def __init__(self, f0):
        n = f0.size
        self.a, self.fa = np.zeros(n), f0.astype(float).copy()
        self.b, self.fb = np.full(n, np.inf), np.full(n, np.nan)
        self.pb = np.full(n, np.nan)  # the arg of the largest multiplier at b
        # Illinois: the end kept last (-1: b, +1: a) and the weights on the ends' values
        self.side, self.wa, self.wb = np.zeros(n), np.ones(n), np.ones(n)
        self.f0 = f0.astype(float).copy()  # log rho at p = 0
        self.b2, self.fb2 = np.full(n, np.inf), np.full(n, np.nan)  # the previous b

    def put(self, idx, P, S):
        """Evaluations S (log multipliers) at P of the pairs idx (a pair at most once):
        each the new lower end where stable above it, the new upper end (or the one
        before it) where unstable below it; returns which were stable."""
        f = S[:, 0].real
        left = f < 0.0
        lo = left & (P > self.a[idx])
        self.a[idx[lo]], self.fa[idx[lo]] = P[lo], f[lo]
        new = ~left & (P < self.b[idx])
        up = idx[new]
        self.b2[up], self.fb2[up] = self.b[up], self.fb[up]
        self.b[up], self.fb[up], self.pb[up] = P[new], f[new], S[new, 0].imag
        second = ~left & ~new & (P < self.b2[idx])
        self.b2[idx[second]], self.fb2[idx[second]] = P[second], f[second]
        return left


def _scan(spectra, h, br, pairs, points=None):
    """The scan of :func:`_first_crossings` over ``pairs`` (flat indices into ``br``, ranges
    ``h[pairs]``): each bracket's first crossing; returns the largest log rho met by each
    pair that found none. ``points``: a list of rounds, each (pairs, k) parameters
    evaluated at once (NaN: none; default :data:`_SCAN`, one a round)."""
    peak = br.fa.copy()
    scan = pairs[br.fa[pairs] < 0.0]
    if points is None:
        points = [x * h[:, None] for x in _SCAN[:, None, None]]
    for r, P in enumerate(points):
        if r == len(points) - 1:  # the last round: the range's end, where not NaN
            scan = scan[np.isfinite(P[scan, 0])]
        if scan.size == 0:
            break
        idx, col = np.nonzero(np.isfinite(P[scan]))
        x = P[scan[idx], col]
        S = spectra(scan[idx], x)  # one call a round
        stable = np.ones(scan.size, bool)
        for c in np.unique(col):  # a column at a time: a pair at most once per put
            at = col == c
            stable[idx[at]] &= br.put(scan[idx[at]], x[at], S[at])
        peak[scan] = np.maximum(peak[scan], br.fa[scan])
        scan = scan[stable]
    return peak


def _refine(spectra, br, todo, xtol, size):
    """Narrow the brackets of the pairs ``todo`` until ``b - a <= xtol * size(pair, b)``.

    Illinois false position on log rho, where the stable end is on the mode that crosses.
    Until it is (log rho at a within 10 % of its nominal value: a mode the margin leaves
    alone, say the slow along-track one, is the largest there, so log rho is flat up to
    the crossing and false position would crawl), the secant through the two latest
    unstable ends (the crossing mode's), else bisection (also for a secant step within
    5 % of the lower end: the secant from above lands near the root, which lies near the
    upper end once it is close). A step is kept half the tolerance inside the bracket."""
    for _ in range(_REFINE):
        todo = todo[(br.b[todo] - br.a[todo]) > xtol * size(todo, br.b[todo])]
        if todo.size == 0:
            break
        lo, up, w = br.a[todo], br.b[todo], br.b[todo] - br.a[todo]
        flo, fup = br.wa[todo] * br.fa[todo], br.wb[todo] * br.fb[todo]
        flat = br.fa[todo] <= br.f0[todo] + 0.1 * np.abs(br.f0[todo])
        with np.errstate(divide="ignore", invalid="ignore"):
            falsi = up - fup * (up - lo) / (fup - flo)
            b2, fb2 = br.b2[todo], br.fb2[todo]
            secant = up - br.fb[todo] * (b2 - up) / (fb2 - br.fb[todo])
        guard = np.where(flat, 0.05 * w, 0.0)  # the secant: not within 5 % of the lower end
        c = np.where(flat, np.where(np.isfinite(b2) & (fb2 > br.fb[todo]), secant, np.nan),
                     falsi)
        c = np.where((c > lo + guard) & (c < up), c, 0.5 * (lo + up))
        # at least half the tolerance inside the bracket: a step that lands on the root
        # then closes it from one side or the other (as Brent's method steps)
        half = 0.5 * xtol * size(todo, up)
        c = np.clip(c, lo + half, up - half)
        left = br.put(todo, c, spectra(todo, c))  # left: c stable, the new a; b kept
        sd = br.side[todo]
        br.wb[todo] = np.where(left, np.where(sd == -1, 0.5, 1.0) * br.wb[todo], 1.0)
        br.wa[todo] = np.where(left, 1.0, np.where(sd == 1, 0.5, 1.0) * br.wa[todo])
        br.side[todo] = np.where(left, -1, 1)


def _check(spectra, br, found, p, h, size):
    """The real loop's bracket around the surrogate's crossings p of the pairs ``found``:
    :data:`_CHECK` either side, widened :data:`_WIDEN` times (4x each) on the side the
    crossing lies beyond; returns the pairs bracketed. The surrogate's error in p is that
    of its log rho over the slope, whatever the margin, while the check's width is
    relative to the margin: a down margin of a few percent left its crossing just outside
    the check, and the whole search ran again on the real loop (on the paper grid's slow
    circles, the longest, 100-140 evaluations a speed against 24)."""
    width = _CHECK * size(found, p)
    lo, up = np.maximum(p - width, 0.0), np.minimum(p + width, h[found])
    both = np.concatenate([found, found])
    S = spectra(both, np.concatenate([lo, up]))  # one call: a pair at most once per put
    br.put(found, lo, S[:found.size])
    br.put(found, up, S[found.size:])
    for _ in range(_WIDEN):
        low, high = br.b[found] <= lo, br.a[found] >= up  # unstable at lo; stable at up
        if not np.any(low | high):
            break
        width = np.where(low | high, 4.0 * width, width)
        lo = np.where(low, np.maximum(p - width, 0.0), lo)
        up = np.where(high, np.minimum(p + width, h[found]), up)
        idx, P = np.concatenate([found[low], found[high]]), np.concatenate([lo[low], up[high]])
        br.put(idx, P, spectra(idx, P))
    return found[(br.a[found] >= lo) & (br.b[found] <= up)]


def first_crossings(spectra, hi, s0, xtol, size, surrogate=None, guess=None, phases=False):
    """The first p in [0, hi] where the loop of ``spectra(pair, p)`` is unstable, searched
    from 0, for every (loop, margin) pair of ``hi`` (b, J) at once: inf where none, NaN
    where the loop is unstable at p = 0 (``s0`` (b, k), its log multipliers there).

    ``spectra(pair, P)``: flat pair indices and parameters (L,) to the log multipliers
    (L, k), largest first (``_log_spectrum`` of :mod:`~gainsched.schedule.margins`: k =
    1). The scan :data:`_SCAN` brackets the first crossing; Illinois false position
    refines it until the bracket is ``xtol * size(pair, p)`` wide (the margin's value at p).

    With a ``surrogate`` (a cheaper ``spectra``, :data:`_SURROGATE_ERROR` from the real
    one) the scan and a first refinement run on it; the real loop then checks a bracket
    of :data:`_CHECK` around each crossing found (widened if it lies just outside) and
    refines it, and a margin the
    surrogate finds no crossing of stands if the surrogate's loop stayed
    :data:`_SURROGATE_ERROR` inside the unit circle at every scan point. Every other
    pair is searched again on the real loop alone.

    A ``guess`` (b, J) of each crossing (NaN: none) scans at :data:`_AROUND` times it
    first, then at the range's end: the bracket starts tight around a good guess (the
    level circle's delay margin for the tilted circles of its speed).

    ``phases``: also the arg of the crossing multiplier (b, J), rad in (-pi, pi] (the
    largest multiplier at the bracket's unstable end; NaN where no crossing)."""
    hi = np.asarray(hi, float)
    nb, J = hi.shape
    h, S0 = hi.reshape(-1), np.repeat(s0, J, axis=0)
    f0, everyone = S0[:, 0].real, np.arange(h.size)
    br = _Brackets(f0)
    points = None
    if guess is not None:
        g = np.asarray(guess, float).reshape(-1)
        ok = (np.isfinite(g) & (g > 0))[:, None]
        points = [np.where(ok, np.minimum(x[None, :] * g[:, None], h[:, None]),
                           np.where(np.arange(x.size) == 0, s * h[:, None], np.nan))
                  for x, s in zip(_AROUND, _SCAN, strict=True)]
        points.append(np.where(ok, h[:, None], np.nan))  # then the range's end
    if surrogate is None:
        _scan(spectra, h, br, everyone, points)
        _refine(spectra, br, np.flatnonzero(np.isfinite(br.b)), xtol, size)
    else:
        sur = _Brackets(f0)
        peak = _scan(surrogate, h, sur, everyone)
        found = np.flatnonzero(np.isfinite(sur.b))
        _refine(surrogate, sur, found, _CHECK / 4, size)
        held = _check(spectra, br, found, 0.5 * (sur.a[found] + sur.b[found]), h, size)
        _refine(spectra, br, held, xtol, size)
        none = np.setdiff1d(np.flatnonzero(f0 < 0.0), found)
        again = np.setdiff1d(np.flatnonzero(f0 < 0.0),
                             np.concatenate([held, none[peak[none] < -_SURROGATE_ERROR]]))
        if again.size:  # the surrogate's answer not confirmed: the real loop alone
            br.a[again], br.fa[again] = 0.0, f0[again]
            br.b[again], br.side[again], br.wa[again], br.wb[again] = np.inf, 0, 1.0, 1.0
            br.b2[again] = np.inf
            _scan(spectra, h, br, again)
            _refine(spectra, br, again[np.isfinite(br.b[again])], xtol, size)
    out = np.where(np.isfinite(br.b), 0.5 * (br.a + br.b), np.inf)
    out[f0 >= 0.0] = np.nan
    if phases:
        return out.reshape(nb, J), np.where(np.isfinite(out), br.pb, np.nan).reshape(nb, J)
    return out.reshape(nb, J)
