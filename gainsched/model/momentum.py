"""Momentum theory's induced velocity (:class:`~gainsched.model.effects.ThrustMomentum`,
paper eq. 29): the largest root of the quartic ``v^2 ((v + vz)^2 + vxy^2) = vh^4``, for
whole arrays of samples, complex-step safe.

The roots are those of the compiled plant's ``gs_induced_velocity``
(``gainsched/native/plant.c``: safeguarded Newton per sample, the one implementation the
model and the simulator's plant share). A build calls this thousands of times on tens to
thousands of samples: the numpy iteration's ~100 array operations a call made the paper
grid's build with momentum theory 3.3x the drag-only one, the compiled roots 2.9x
(docs/performance.md). The numpy fallback: most samples (every one
where the root is unique) take plain Newton steps from Glauert's estimate on whole
arrays; the rest (the vortex ring, where three roots may exist, and any sample whose
plain Newton did not converge inside the bracket) a safeguarded Newton with bisection
from the bracket's top. No library solves a batch of quartics for one chosen real root at
this cost (``numpy.roots`` is one companion matrix per sample).
"""

from __future__ import annotations

import ctypes

import numpy as np

from .. import native

__all__ = ["induced_velocity"]

#: convergence, relative to vh, and safeguarded steps at most: those of the compiled plant
TOL, MAX_ITER = 1e-12, 80


def _compiled(vh, vz, vxy2):
    """The roots by the compiled plant (1-d float arrays), or None without it."""
    lib = native.load("plant")
    if lib is None:
        return None
    fn = lib.gs_induced_velocity
    if fn.argtypes is None:  # addresses as integers: data_as() costs ~7 us a pointer
        fn.argtypes = [ctypes.c_ssize_t] + [ctypes.c_void_p] * 4
    v = np.empty(vh.size)
    vh, vz, vxy2 = (np.ascontiguousarray(x, dtype=float) for x in (vh, vz, vxy2))
    fn(vh.size, vh.ctypes.data, vz.ctypes.data, vxy2.ctypes.data, v.ctypes.data)
    return v


def _newton_bisect(v, lo, hi, vh2, vz, vxy2):
    """One safeguarded Newton step for g(v) = v^2 ((v + vz)^2 + vxy^2) - vh^4 (real parts
    decide, so complex-step perturbations ride along): (v, lo, hi). A Newton step that
    stays in the closed bracket is taken (a converged step of zero included), else the
    bracket is bisected."""
    w = v + vz
    g = v * v * (w * w + vxy2) - vh2 * vh2
    dg = 2 * v * (w * w + vxy2) + 2 * v * v * w
    pos = np.real(g) > 0
    hi = np.where(pos, v, hi)
    lo = np.where(pos, lo, v)
    good = np.real(dg) > 0
    newton = v - g / np.where(good, dg, 1.0)
    nr = np.real(newton)
    ok = good & (nr >= np.real(lo)) & (nr <= np.real(hi))
    return np.where(ok, newton, 0.5 * (lo + hi)), lo, hi


def _newton_plain(v, vh2, vz, vxy2, tol_v, judged, max_steps=8):
    """Plain Newton steps for g(v) = v^2 ((v + vz)^2 + vxy^2) - vh^4 from ``v`` (all
    arrays of one shape, real) until every sample where ``judged`` moves by at most
    ``tol_v``: ``(v, converged)``, converged where the last step was within ``tol_v``
    (a sample not judged may run off: its g' may vanish)."""
    vh4 = vh2 * vh2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(max_steps):
            w = v + vz
            q = w * w + vxy2
            step = (v * v * q - vh4) / (2 * v * (q + v * w))  # g / g'
            v = v - step
            converged = np.abs(step) <= tol_v
            if (converged | ~judged).all():
                break
    return v, converged


def _bracketed(v, lo, hi, a, b, c, h, tol, max_iter):
    """Safeguarded Newton (:func:`_newton_bisect`) from ``v`` in ``[lo, hi]`` (1-d
    arrays; ``a, b, c, h``: vh^2, vz, vxy^2, vh), whole arrays while every sample moves,
    then only the samples not converged yet: the root, shape of ``v``."""
    steps = 0
    moving = np.ones(v.shape, dtype=bool)
    while steps < max_iter:  # whole arrays while every sample moves
        vn, lo, hi = _newton_bisect(v, lo, hi, a, b, c)
        moving = np.abs(vn - v) > tol * h
        v = vn
        steps += 1
        if not moving.all():
            break
    idx = np.flatnonzero(moving)
    for _ in range(steps, max_iter):  # then only the samples not converged yet
        if idx.size == 0:
            break
        vn, lo[idx], hi[idx] = _newton_bisect(v[idx], lo[idx], hi[idx], a[idx], b[idx], c[idx])
        moving = np.abs(vn - v[idx]) > tol * h[idx]
        v[idx] = vn
        idx = idx[moving]
    return v


def induced_velocity(vh, vz, vxy2, tol=TOL, max_iter=MAX_ITER):
    """Induced velocity v_i of :class:`~gainsched.model.effects.ThrustMomentum`: the
    largest root of g(v) = v^2 ((v + vz)^2 + vxy^2) - vh^4 in [0, vh + max(0, -vz)].

    g' = 2 v (2 v^2 + 3 v vz + vz^2 + vxy^2) >= 0 on v > 0 when ``vz >= 0`` or ``8 vxy^2 >=
    vz^2`` (the bracket's minimum over v is ``vxy^2 - vz^2 / 8``): there g has one root and
    plain Newton starts from Glauert's estimate ``vh^2 / |(vxy, vh + vz)|`` (exact in hover
    and in fast forward flight; about five steps to 1e-12). Elsewhere (descent along the
    rotor axis, the vortex ring) there may be three roots, and a safeguarded Newton starts
    from the bracket's top, so that the largest is found; so do the samples whose plain
    Newton did not converge or left the bracket. Complex inputs (a complex step): the root
    of the real parts and its first-order change by the implicit function theorem.

    Parameters
    ----------
    vh : array_like, shape (...), m/s
        Hover induced velocity (> 0).
    vz : array_like, shape (...), m/s
        Airspeed along the rotor axis (positive: the air meets the disk from above).
    vxy2 : array_like, shape (...), m^2/s^2
        Squared in-plane airspeed.
    tol : float
        Convergence: the last Newton step within ``tol * vh``.
    max_iter : int
        Steps of the safeguarded iteration at most. With both at their defaults the
        compiled plant solves (when it is built), else the numpy iteration.

    Returns
    -------
    ndarray, broadcast shape of the inputs, m/s (complex for complex inputs)
    """
    vh, vz, vxy2 = np.broadcast_arrays(vh, vz, vxy2)
    if np.iscomplexobj(vh) or np.iscomplexobj(vz) or np.iscomplexobj(vxy2):
        # a complex step: the root of the real parts, then its first-order change by the
        # implicit function theorem, Im v = -Im g(v_r; inputs) / g'(v_r) (exact to the
        # step's O(h^2), as iterating in complex arithmetic would be, at one evaluation)
        v = induced_velocity(np.real(vh), np.real(vz), np.real(vxy2), tol, max_iter)
        w = v + vz
        g = v * v * (w * w + vxy2) - vh ** 4
        dg = 2 * v * (w * w + vxy2) + 2 * v * v * w
        return v - 1j * np.imag(g) / np.real(dg)
    shape = vh.shape
    b, c, h = vz.reshape(-1), vxy2.reshape(-1), vh.reshape(-1)
    if tol == TOL and max_iter == MAX_ITER and (v := _compiled(h, b, c)) is not None:
        return v.reshape(shape)
    a = h * h
    hi = h + 0.5 * (np.sqrt(b * b + 1e-12) - b)
    glauert = a / np.sqrt(c + (h + b) ** 2 + 1e-12)
    one_root = (b >= 0) | (8 * c >= b * b)
    v, ok = _newton_plain(glauert, a, b, c, tol * h, one_root)
    rest = np.flatnonzero(~(ok & one_root & (v >= 0) & (v <= hi)))
    if rest.size:  # the vortex ring, and any plain Newton that failed: from the old start
        start = np.where(one_root[rest], glauert[rest], hi[rest])
        v[rest] = _bracketed(start, np.zeros(rest.size), hi[rest], a[rest], b[rest], c[rest],
                             h[rest], tol, max_iter)
    return v.reshape(shape)
