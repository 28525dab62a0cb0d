"""Stability margins of a periodic closed loop, broken at the plant input.

The table's closed loop of a circle is the periodic discrete system of the solver
(:mod:`gainsched.schedule.lqr`): ``x_{k+1} = (A_k - B_k K_k) x_k`` over the N samples of
one period, stable when the monodromy ``Phi = prod_k (A_k - B_k K_k)`` has its Floquet
multipliers inside the unit circle. A flight controller is signed off on how far that is
from instability, broken where the controller meets the vehicle, the thrust commands:

- **gain margins**: the loop ``x_{k+1} = (A_k - B_k G K_k) x_k`` with ``G = g I`` (all four
  motors at once) or ``G = diag(1, .., g, .., 1)`` (one motor): the factors ``g_down < 1 <
  g_up`` nearest to 1 at which a multiplier reaches the unit circle (the motors' thrust
  per command that much weaker or stronger than the model's);
- **delay margin**: the extra delay ``tau`` on the commands, ``u_applied(t) = u(t - tau)``,
  on top of what the model holds, at which a multiplier reaches the unit circle. At the
  sample step h of the period, ``tau = (d + f) h``: the commands are held d samples, and
  the fraction f is applied as the linear mix ``(1 - f) u_{k-d} + f u_{k-d-1}`` of two
  held commands (exact at whole samples, first order in between: the ZOH integral of a
  shift inside one sample is split in proportion to time, not through ``exp(A s)``).

Each margin is a root of ``log rho(Phi(p))`` in the parameter p (g or tau), found for
every circle and every margin of a batch at once: a scan of the parameter (the first
crossing, which the nearest instability is) and the Illinois variant of false position
inside the bracket it finds (superlinear; the monodromies of all unfinished margins in
one call of the compiled kernel ``gainsched/native/loops.c``, with a numpy fallback). The
products are kept as ``M 2^e`` (exact power-of-two rescaling every few steps), so a
loop far beyond its margin does not overflow. Why by hand: python-control and MATLAB's
``margin``/``diskmargin`` give these for time-invariant loops only; the periodic loop's
margins are those of its monodromy, which no library forms.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, fields

import numpy as np

from .. import native
from ..constants import MARGIN_DELAY_MAX_S, MARGIN_GAIN_MAX
from ..errors import GainschedError
from .crossings import first_crossings

__all__ = ["loop_log_rho", "monodromy_with", "spectral_radius", "gain_margins", "delay_margin",
           "loop_margins", "LoopMargins", "crossover_frequency",
           "G_MAX", "TAU_MAX_S", "XTOL", "MARGIN_XTOL", "MARGIN_DELAY_XTOL",
           "SURROGATE_SPAN_S", "surrogate_block"]

#: the largest gain factor searched (+20 dB); no crossing below it: margin reported inf
G_MAX = MARGIN_GAIN_MAX
#: the longest extra delay searched, s; no crossing below it: margin reported inf
TAU_MAX_S = MARGIN_DELAY_MAX_S
#: the default tolerance on a margin, relative to its value
XTOL = 1e-10
#: the build's tolerances, relative: 1e-6 of a gain factor (1e-5 dB) and 1e-4 of a delay
#: (1.5 us on the paper's 15 ms)
MARGIN_XTOL = 1e-6
MARGIN_DELAY_XTOL = 1e-4
#: the gain scan's surrogate: blocks of this span of control steps, s, each the power of
#: its middle step's loop (32 steps at 1 kHz: about 7x cheaper than every step; its log
#: rho is within 1e-4 of the loop's on the paper's circles;
#: :func:`~gainsched.schedule.crossings.first_crossings`). A span, not a count: how far
#: the loop moves inside a block is a matter of time, and at 8 kHz 32 steps would leave
#: the surrogate 8x the work for the same accuracy
SURROGATE_SPAN_S = 0.032
#: steps between the numpy fallback's rescalings (the kernel's RENORM)
_RENORM = 16


def surrogate_block(h) -> int:
    """Steps per block of the gain scan's surrogate at the step ``h`` (s): those of
    :data:`SURROGATE_SPAN_S`, at least 1.

    Examples
    --------
    >>> surrogate_block(0.001), surrogate_block(1 / 8000)
    (32, 256)
    """
    return max(1, int(round(SURROGATE_SPAN_S / float(np.min(h)))))


def spectral_radius(M):
    """Largest eigenvalue modulus of square matrices (..., n, n)."""
    return np.abs(np.linalg.eigvals(M)).max(-1)


def monodromy_with(Ad, Bd, K, gain):
    """``prod_k (A_k - B_k diag(gain) K_k)`` over the period, shape ``(*batch, n, n)``.

    Parameters
    ----------
    Ad : ndarray, shape (*b, N, n, n)
    Bd : ndarray, shape (*b, N, n, m)
    K : ndarray, shape (*b, N, m, n)
        The period's samples (the solver's discretisation and gains).
    gain : ndarray, shape (*batch, m)
        The factor on each input; ``*batch`` broadcasts against ``*b``.
    """
    gain = np.asarray(gain, float)
    n = Ad.shape[-1]
    batch = np.broadcast_shapes(Ad.shape[:-3], gain.shape[:-1])
    M = np.broadcast_to(np.eye(n), batch + (n, n)).copy()
    for k in range(Ad.shape[-3]):
        BG = Bd[..., k, :, :] * gain[..., None, :]
        M = (Ad[..., k, :, :] - BG @ K[..., k, :, :]) @ M
    return M


def _rescaled(M, e):
    """``M 2^-p``, ``e + p`` with 2^p the power of two above max |M| per matrix."""
    mx = np.abs(M).max(axis=(-2, -1))
    p = np.where((mx > 0) & np.isfinite(mx), np.frexp(np.where(mx > 0, mx, 1.0))[1], 0)
    return np.ldexp(M, -p[..., None, None]), e + p


def _log_spectrum(M, e):
    """The largest multiplier of ``M 2^e`` as a complex log, ``log|lambda| + i arg
    lambda`` (L, 1) (the first of equals; -inf for a nilpotent product): its real part
    is what the searches bracket, its arg the crossing's frequency."""
    lam = np.linalg.eigvals(M)
    with np.errstate(divide="ignore"):
        out = np.log(lam.astype(complex)) + (e * np.log(2.0))[..., None]
    out = np.where(lam == 0, complex(-np.inf, 0.0), out)
    key = np.where(np.isnan(out.real), -np.inf, out.real)  # a NaN last, as a sort puts it
    return np.take_along_axis(out, np.argmax(key, axis=-1)[..., None], -1)


def _log_rho(M, e):
    """``log rho(M 2^e)``; -inf for a nilpotent product."""
    return _log_spectrum(M, e)[..., 0].real


def _lib():
    lib = native.load("loops")
    if lib is not None and not hasattr(lib, "_gs_ready"):
        dp, sp, i, z = (ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_ssize_t),
                        ctypes.c_int, ctypes.c_ssize_t)
        ip = ctypes.POINTER(ctypes.c_int)
        lib.gs_gain_loops.argtypes = [i, i, i, i, z, z, z, ip, dp, sp, dp, sp, dp, sp, dp, dp,
                                      dp]
        lib.gs_delay_loops.argtypes = [i, i, i, i, i, z, z, z, ip, dp, sp, dp, sp, dp, sp, dp,
                                       dp, dp, dp]
        lib._gs_ready = True
    return lib


def _c(X):
    """X as float64 with whole-element strides: (array, pointer, strides)."""
    X = np.asarray(X, dtype=float)
    if any(s % X.itemsize for s in X.strides):
        X = np.ascontiguousarray(X)
    return X, X.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), (
        ctypes.c_ssize_t * X.ndim)(*(s // X.itemsize for s in X.strides))


def _out(*shape):
    X = np.empty(shape)
    return X, X.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _gain_loops(Ad, Bd, K, circle, G, block=1):
    """``log rho`` of the lanes: loop ``circle`` (L,) with the factors G (L, m): (L,)."""
    return _gain_spectra(Ad, Bd, K, circle, G, block)[:, 0].real


def _gain_spectra(Ad, Bd, K, circle, G, block=1):
    """The largest log multiplier (:func:`_log_spectrum`) of the lanes: loop ``circle``
    (L,) with the factors G (L, m); ``block`` > 1: the scan's surrogate, the period in
    blocks of that many steps, each the power of its middle step's loop."""
    _, N, n, m = Bd.shape
    L = circle.size
    lib = _lib()
    if lib is None:
        M, e, since = np.broadcast_to(np.eye(n), (L, n, n)).copy(), np.zeros(L), 0
        for k in range(0, N, block):
            ln = min(block, N - k)
            mid = k + ln // 2
            F = Ad[circle, mid] - (Bd[circle, mid] * G[:, None, :]) @ K[circle, mid]
            M = (F if ln == 1 else np.linalg.matrix_power(F, ln)) @ M
            since += ln
            if since >= _RENORM:
                M, e, since = *_rescaled(M, e), 0
        return _log_spectrum(M, e)
    (Ad, pa, sa), (Bd, pb, sb), (K, pk, sk) = _c(Ad), _c(Bd), _c(K)
    G, pg, _ = _c(np.ascontiguousarray(G, dtype=float))
    circle = np.ascontiguousarray(circle, dtype=np.intc)
    (M, pm), (e, pe) = _out(L, n, n), _out(L)
    if lib.gs_gain_loops(n, m, N, block, L, 0, L,
                         circle.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
                         pa, sa, pb, sb, pk, sk, pg, pm, pe) != 0:
        raise GainschedError(f"loop kernel: size n={n}, m={m} beyond its limits")
    return _log_spectrum(M, e)


def loop_log_rho(Ad, Bd, K):
    """``log rho`` of periodic closed loops ``prod_k (A_k - B_k K_k)``, overflow-safe (the
    compiled kernel; numpy without it).

    Parameters
    ----------
    Ad, Bd, K : ndarray
        Shapes (b, N, n, n), (b, N, n, m), (b, N, m, n).

    Returns
    -------
    ndarray, shape (b,)
        The log of each loop's largest multiplier (< 0: stable).
    """
    b, m = Ad.shape[0], Bd.shape[-1]
    return _gain_loops(Ad, Bd, K, np.arange(b), np.ones((b, m)))


#: columns the delayed loop's monodromy is applied to, above the loop's states
#: (:func:`_columns`): its numerical rank over a period is about theirs and one or two
#: delay modes (12-13 on the paper's circles of 11 states; a motor lag's 15 states left 14
#: columns short, and the whole monodromy was formed)
_RANK_ABOVE = 3


def _columns(n: int) -> int:
    """The columns the delayed loop of ``n`` states is applied to (14 for the paper's
    11, 18 with a motor lag's four more)."""
    return n + _RANK_ABOVE

#: the span, s, over which the delayed loop's fast and delay modes decay far below the
#: 1e-9 of :func:`_delay_spectra`'s check (:func:`_decay_steps`): a time-invariant loop's
#: delay margin is searched on its step's power over it (the paper's level circles at 1
#: and 4 kHz, 3 and 15 m/s, at their delay margin: the 15th multiplier 4e-15 to 7e-12 at
#: 0.25 s, 1e-29 to 5e-23 at 0.5 s, 2e-6 to 4e-5 at 0.1 s), and a periodic loop's image
#: is found over the last span of its period (tilted 10 and 20 deg at 5-15 m/s, 15 ms of
#: delay: off the span 4e-10 to 7e-15 at 0.2-0.4 s, 3e-2 at 0.03 s)
_DECAY_SPAN_S = 0.3
#: and at least this many times the delay evaluated: a delay mode's multiplier over a span
#: falls like j^(-span / tau) (the j-th root of a retarded loop), so the span grows with
#: the delay (0.3 s is 20 of the paper's 15 ms margins; at 8 kHz and the scan's 25-50 ms,
#: 0.3 s left the 15th multiplier above the check, and the one-step matrix of 1615 rows
#: was formed)
_DECAY_DELAYS = 20


def _delay_pass_numpy(Ad, Bd, K, circle, tau, D, X0):
    """The recursion of ``gs_delay_loops`` in ``native/loops.c`` with numpy (the fallback):
    the lanes' columns propagated over the period with a ring of the last commands."""
    _, N, n, m = Bd.shape
    L, p, R = tau.size, X0.shape[-1], D + 1
    d = np.floor(tau).astype(int)
    f = (tau - d)[:, None, None]
    X = X0[:, :n].copy()
    ring = np.zeros((R, L, m, p))
    for j in range(1, D + 1):
        ring[R - j] = X0[:, n + (j - 1) * m:n + j * m]
    e, lanes = np.zeros(L), np.arange(L)
    for k in range(N):
        ring[k % R] = -(K[circle, k] @ X)
        app = (1.0 - f) * ring[(k - d) % R, lanes] + f * ring[(k - d - 1) % R, lanes]
        X = Ad[circle, k] @ X + Bd[circle, k] @ app
        if (k + 1) % _RENORM == 0:
            mx = np.maximum(np.abs(X).max(axis=(1, 2)), np.abs(ring).max(axis=(0, 2, 3)))
            q = np.where((mx > 0) & np.isfinite(mx), np.frexp(np.where(mx > 0, mx, 1.0))[1], 0)
            X, ring, e = np.ldexp(X, -q[:, None, None]), np.ldexp(ring, -q[:, None, None]), e + q
    regs = [ring[(N - j) % R] for j in range(1, D + 1)]
    return np.concatenate([X, *regs], axis=1), e


def _delay_pass(lib, Ad, Bd, K, circle, tau, D, X0):
    """The delayed monodromy of each lane applied to X0 (L, na, p): ``(Y, e)``,
    ``M X0 = Y 2^e`` (the compiled kernel, or :func:`_delay_pass_numpy` without it)."""
    if lib is None:
        return _delay_pass_numpy(Ad, Bd, K, circle, tau, D, X0)
    _, N, n, m = Bd.shape
    L, p = tau.size, X0.shape[-1]
    (Ad, pa, sa), (Bd, pb, sb), (K, pk, sk) = _c(Ad), _c(Bd), _c(K)
    (tau, pt, _), (X0, px, _) = _c(np.ascontiguousarray(tau)), _c(np.ascontiguousarray(X0))
    circle = np.ascontiguousarray(circle, dtype=np.intc)
    (Y, py), (e, pe) = _out(*X0.shape), _out(L)
    rc = lib.gs_delay_loops(n, m, N, D, p, L, 0, L,
                            circle.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
                            pa, sa, pb, sb, pk, sk, pt, px, py, pe)
    if rc != 0:
        raise GainschedError(f"loop kernel: delay of {tau.max():g} samples failed ({rc})")
    return Y, e


def _delay_loops(Ad, Bd, K, circle, tau):
    """``log rho`` of the lanes: loop ``circle`` (L,) with the delays tau (L,) in samples."""
    return _delay_spectra(Ad, Bd, K, circle, tau)[:, 0].real


def _decay_steps(h) -> int:
    """The steps of :data:`_DECAY_SPAN_S` at the shortest step ``h`` (s): a time-invariant
    loop's power, a periodic loop's span to find its image on (:func:`_delay_spectra`)."""
    return max(1, int(np.ceil(_DECAY_SPAN_S / float(np.min(h)))))


def _delay_spectra(Ad, Bd, K, circle, tau, decay=1):
    """The largest log multiplier (:func:`_log_spectrum`) of the lanes: loop ``circle``
    (L,) with the delays tau (L,) in samples.

    The delayed loop's monodromy has n + D m rows, but over a period its fast modes have
    decayed: it is numerically of low rank. It is applied to :func:`_columns` (the
    orthonormal basis Q of its image: one step of subspace iteration from a fixed random
    start) and its multipliers are those of ``Q' M Q``; where ``M Q`` leaves the span of Q
    by more than 1e-9 of its norm, the whole monodromy is formed instead. The span of the
    fast modes' decay (``decay`` steps, :func:`_decay_steps`, or :data:`_DECAY_DELAYS`
    times the longest delay in samples if that is more) is all that shapes the image: the
    start is propagated over the period's last span alone (the whole period if the check
    fails on it), then Q over the period.

    A time-invariant loop (N = 1): the same on its step's power over the span, whose
    multipliers are the step's to that power: the log of the largest over the power, with
    the arg of the step's own multiplier (the Rayleigh quotient of one step on the power's
    eigenvector; the power's arg is that times the power, modulo 2 pi). The one-step
    matrix of n + D m rows has as many multipliers as rows (815 at 4 kHz and the 50 ms
    searched: its eigenvalues were 4x the rest of the build); its power needs the 14
    columns."""
    n, m, N = Ad.shape[-1], Bd.shape[-1], Ad.shape[-3]
    D = int(np.floor(tau.max())) + 1
    na, L = n + D * m, tau.size
    lib = _lib()
    span = max(decay, int(np.ceil(_DECAY_DELAYS * tau.max())))
    power = span if N == 1 else 1
    cols = _columns(n)
    if na > cols:
        steps = tuple(X if power == 1 else np.broadcast_to(X[:, :1], X.shape[:1] + (power,)
                                                             + X.shape[2:])
                      for X in (Ad, Bd, K))
        omega = np.linalg.qr(np.random.default_rng(0).standard_normal((na, cols)))[0]
        start = np.broadcast_to(omega, (L,) + omega.shape)
        for w in dict.fromkeys((min(span, N * power), N * power)):
            Y, _ = _delay_pass(lib, *(X[:, X.shape[1] - w:] for X in steps), circle, tau, D,
                               start)
            Q = np.linalg.qr(Y)[0]
            Z, e = _delay_pass(lib, *steps, circle, tau, D, Q)
            QB = np.swapaxes(Q, -1, -2) @ Z
            off = np.linalg.norm(Z - Q @ QB, axis=(-2, -1))
            if np.all(off <= 1e-9 * np.linalg.norm(Z, axis=(-2, -1))):
                if power == 1:
                    return _log_spectrum(QB, e)
                return _one_step(lib, Ad, Bd, K, circle, tau, D, Q, QB, e, power)
    M, e = _delay_pass(lib, Ad, Bd, K, circle, tau, D, np.broadcast_to(np.eye(na), (L, na, na)))
    return _log_spectrum(M, e)


def _one_step(lib, Ad, Bd, K, circle, tau, D, Q, QB, e, power):
    """The largest log multiplier of time-invariant delayed loops (one step each) from
    the Rayleigh-Ritz pair ``Q, QB`` (``QB 2^e``) of their step's ``power``-th power
    (:func:`_delay_spectra`): ``log|mu| / power + i arg lambda``, mu the power's largest
    multiplier and lambda the step's Rayleigh quotient on mu's eigenvector."""
    w, Yv = np.linalg.eig(QB)
    with np.errstate(divide="ignore"):
        logw = np.log(np.abs(w)) + (e * np.log(2.0))[:, None]
    j = np.argmax(np.where(np.isnan(logw), -np.inf, logw), axis=-1)
    v = Q @ np.take_along_axis(Yv, j[:, None, None], -1)  # (L, na, 1), complex
    Fv, _ = _delay_pass(lib, Ad, Bd, K, circle, tau, D,
                        np.concatenate([v.real, v.imag], axis=-1))
    lam = np.sum(v.conj()[..., 0] * (Fv[..., 0] + 1j * Fv[..., 1]), -1) / np.sum(
        np.abs(v[..., 0]) ** 2, -1)
    mag = np.take_along_axis(logw, j[:, None], -1)[:, 0] / power
    return (mag + 1j * np.angle(lam))[:, None]


def _gain_kinds(m):
    """Masks (J, m) and directions (J,) of the gain margins: all inputs down and up,
    then each input down and up."""
    masks = np.concatenate([np.ones((2, m), bool), np.repeat(np.eye(m, dtype=bool), 2, 0)])
    return masks, np.tile([-1.0, 1.0], m + 1)


def _nominal(Ad, Bd, K):
    """The largest log multiplier of each loop as it is (b, 1)."""
    b, m = Ad.shape[0], Bd.shape[-1]
    return _gain_spectra(Ad, Bd, K, np.arange(b), np.ones((b, m)))


def _gain_crossings(Ad, Bd, K, masks, sign, g_max, s0, xtol, block):
    """The first crossing of each gain margin (J kinds) from 1, as ``p = |g - 1|``: (b, J);
    ``block`` > 1: scanned on the surrogate of that block length first."""
    J = sign.size
    hi = np.broadcast_to(np.where(sign < 0, 1.0, g_max - 1.0), (Ad.shape[0], J))

    def loops(block):
        def spectra(pair, P):
            circle, kind = np.divmod(pair, J)
            G = np.where(masks[kind], (1.0 + sign[kind] * P)[:, None], 1.0)
            return _gain_spectra(Ad, Bd, K, circle, G, block)
        return spectra

    def size(pair, P):  # the factor g at P
        return np.maximum(1.0 + sign[pair % J] * P, 1e-12)

    surrogate = loops(block) if block > 1 and Ad.shape[-3] >= 4 * block else None
    return first_crossings(loops(1), hi, s0, xtol, size, surrogate)


def _delay_crossings(Ad, Bd, K, hi_steps, s0, xtol, guess_steps=None, decay=1):
    """The first crossing of the delay margin, samples, and the arg of the multiplier that
    crosses, rad: (b,) each; ``guess_steps`` (b,) of it (NaN: none) start the scan
    around it; ``decay``: the steps of the fast modes' decay (:func:`_delay_spectra`)."""
    def spectra(pair, P):
        return _delay_spectra(Ad, Bd, K, pair, P, decay)

    def size(pair, P):  # the delay, samples (at least one)
        return np.maximum(P, 1.0)

    guess = None if guess_steps is None else np.asarray(guess_steps, float)[:, None]
    steps, phase = first_crossings(spectra, hi_steps[:, None], s0, xtol, size, guess=guess,
                                   phases=True)
    return steps[:, 0], phase[:, 0]


def crossover_frequency(phase, N: int, h, guess=None):
    """The frequency of the multiplier ``exp(i phase)`` that crosses the unit circle at the
    delay margin: the loop's crossover, rad/s.

    A time-invariant loop (``N = 1``) has it exactly, ``|phase| / h``. A periodic loop's
    Floquet exponent is defined up to ``2 pi / T`` (T = N h, the period) and, its
    multipliers coming in conjugate pairs, up to its sign: the aliases are ``|+-phase + 2
    pi k| / T``, neighbours ``min(2 |phase|, 2 pi - 2 |phase|) / T`` or more apart. Its
    crossover is the alias nearest ``guess`` (the build's: its level circle's,
    time-invariant, of the same speed: the mode continued from the level circle), NaN
    without one.

    Parameters
    ----------
    phase : ndarray, shape (b,)
        The crossing multiplier's arg, rad (NaN: no crossing).
    N : int
        Steps per period.
    h : float or ndarray, shape (b,)
        The step, s.
    guess : float or ndarray, shape (b,), optional
        A guess of each crossover, rad/s.

    Returns
    -------
    ndarray, shape (b,)
        rad/s; NaN where no crossing, none could be chosen, or the multiplier is real at
        zero frequency (no crossover: the phase margin is undefined).

    Examples
    --------
    A loop of 100 steps of 2 ms whose multiplier crosses at arg 1 rad, near 60 rad/s: the
    alias 1 + 2 pi 3 rad over the period of 0.2 s, 99.2 rad/s, is not the one; 1 + 2 pi 2:

    >>> w = gs.crossover_frequency(np.array([1.0]), 100, 0.002, guess=70.0)
    >>> np.round(w, 2).tolist(), round((1 + 4 * np.pi) / 0.2, 2)
    ([67.83], 67.83)
    """
    phase = np.asarray(phase, float)
    if N == 1:
        w = np.abs(phase) / h
    else:
        T = N * np.asarray(h, float)
        g = np.full(phase.shape, np.nan) if guess is None else np.asarray(guess, float) * T
        cands = [np.abs(sgn * phase + 2 * np.pi * np.round((g - sgn * phase) / (2 * np.pi)))
                 for sgn in (1.0, -1.0)]  # either of the conjugate pair
        with np.errstate(invalid="ignore"):
            w = np.where(np.abs(cands[0] - g) <= np.abs(cands[1] - g), *cands) / T
    with np.errstate(invalid="ignore"):
        return np.where(w > 1e-9, w, np.nan)


def _flat(Ad, Bd, K):
    """The loops' batch shape, and their steps flat over it (views where the arrays allow:
    the kernels read any whole-element strides, rows of contiguous entries fastest)."""
    return Ad.shape[:-3], tuple(X.reshape((-1,) + X.shape[-3:]) for X in (Ad, Bd, K))


def gain_margins(Ad, Bd, K, *, inputs=None, g_max: float = G_MAX, xtol: float = XTOL,
                 block: int = 1):
    """The gain margins of periodic closed loops: ``(down, up)``, the factors on the
    commanded inputs nearest to 1 at which a Floquet multiplier reaches the unit circle.

    Parameters
    ----------
    Ad, Bd, K : ndarray
        As :func:`monodromy_with`: shapes (*b, N, n, n), (*b, N, n, m), (*b, N, m, n).
    inputs : sequence of int, optional
        The inputs the factor acts on (default: all at once; ``[j]``: input j alone).
    g_max : float
        The largest factor searched upward.
    xtol : float
        Tolerance on each margin, relative to its factor.
    block : int
        1: every evaluation on the loop itself; > 1: the scan on the surrogate of blocks
        of that many steps first (:func:`surrogate_block`), its crossings checked and
        refined on the loop.

    Returns
    -------
    down, up : ndarray, shape (*b,)
        ``down`` in [0, 1) (0: stable with those inputs off, no lower margin), ``up`` in
        (1, g_max] (inf: stable up to ``g_max``); NaN where the loop is unstable as it
        is. In dB: ``20 log10``.

    Examples
    --------
    A scalar loop ``x+ = a x - g b k x`` is stable while ``|a - g b k| < 1``: its margins
    are ``(a - 1) / (b k)`` and ``(a + 1) / (b k)``, for every period length:

    >>> a, b, k = 1.1, 0.5, 1.2
    >>> Ad, Bd, K = (np.full((1, 4, 1, 1), x) for x in (a, b, k))
    >>> down, up = gain_margins(Ad, Bd, K)
    >>> bool(np.allclose([down[0], up[0]], [(a - 1) / (b * k), (a + 1) / (b * k)]))
    True
    """
    shape, (Ad, Bd, K) = _flat(Ad, Bd, K)
    m = Bd.shape[-1]
    mask = np.zeros(m, bool)
    mask[list(range(m)) if inputs is None else list(inputs)] = True
    p = _gain_crossings(Ad, Bd, K, np.stack([mask, mask]), np.array([-1.0, 1.0]), g_max,
                        _nominal(Ad, Bd, K), xtol, block)
    down = np.where(np.isinf(p[:, 0]), 0.0, 1.0 - p[:, 0])
    return down.reshape(shape), (1.0 + p[:, 1]).reshape(shape)


def delay_margin(Ad, Bd, K, h, *, tau_max: float = TAU_MAX_S, xtol: float = XTOL):
    """The delay margin of periodic closed loops: the extra delay on the commands, s, at
    which a Floquet multiplier first reaches the unit circle.

    Parameters
    ----------
    Ad, Bd, K : ndarray
        As :func:`monodromy_with`.
    h : float or ndarray, shape (*b,)
        The sample step of each loop's period (its period over N), s.
    tau_max : float
        The longest delay searched, s.
    xtol : float
        Tolerance on the delay, relative to max(1 sample, the delay).

    Returns
    -------
    ndarray, shape (*b,)
        The margin, s (inf: stable up to ``tau_max``; NaN: unstable as it is).

    Examples
    --------
    The scalar loop ``x+ = a x - b k u_{k-d}`` with a whole-sample delay d is stable
    while the roots of ``z^(d+1) - a z^d + b k`` are: for a = 1, b k = 0.5 their
    largest modulus is 0.94 at d = 2 and 1.02 at d = 3, so the margin lies between 2 and 3
    samples:

    >>> Ad, Bd, K = np.ones((1, 3, 1, 1)), np.full((1, 3, 1, 1), 0.5), np.ones((1, 3, 1, 1))
    >>> tau = delay_margin(Ad, Bd, K, 0.01)
    >>> bool(0.02 < tau[0] < 0.03)
    True
    """
    shape, (Ad, Bd, K) = _flat(Ad, Bd, K)
    h = np.broadcast_to(np.asarray(h, float), shape).reshape(-1)
    steps, _ = _delay_crossings(Ad, Bd, K, tau_max / h, _nominal(Ad, Bd, K), xtol,
                                decay=_decay_steps(h))
    return (steps * h).reshape(shape)


@dataclass(frozen=True)
class LoopMargins:
    """The margins of periodic closed loops broken at the plant input
    (:func:`loop_margins`); shapes over the batch ``*b`` of loops.

    Attributes
    ----------
    gain_down, gain_up : ndarray, shape (*b,)
        Factors on all inputs at once: ``gain_down`` in [0, 1) (0: stable with the
        feedback off), ``gain_up`` in (1, :data:`G_MAX`] or inf (stable up to it); NaN
        where the loop is unstable as it is.
    input_down, input_up : ndarray, shape (*b, m)
        The same for each input alone (the others at 1).
    delay : ndarray, shape (*b,)
        Extra delay on the commands, s (inf: stable up to :data:`TAU_MAX_S`).
    crossover : ndarray, shape (*b,), or None
        The frequency of the multiplier that crosses at the delay margin, rad/s
        (:func:`crossover_frequency`; NaN where none); None: not computed.
    """

    gain_down: np.ndarray
    gain_up: np.ndarray
    input_down: np.ndarray
    input_up: np.ndarray
    delay: np.ndarray
    crossover: np.ndarray | None = None

    @property
    def phase(self) -> np.ndarray | None:
        """The phase margin the delay margin implies at the crossover, ``crossover *
        delay``, rad (NaN where no crossover; None without crossovers)."""
        return None if self.crossover is None else self.crossover * self.delay

    def at(self, *index) -> LoopMargins:
        """The margins of one loop (or a slice): every array indexed by ``index``."""
        return LoopMargins(*(None if getattr(self, f.name) is None else
                             getattr(self, f.name)[index] for f in fields(self)))



def loop_margins(Ad, Bd, K, h, *, g_max: float = G_MAX, tau_max: float = TAU_MAX_S,
                 xtol: float = XTOL, delay_xtol: float | None = None, block: int = 1,
                 delay_guess: float | None = None, crossover_guess=None,
                 monodromy=None) -> LoopMargins:
    """Every margin of periodic closed loops at once: the gain margins of all inputs
    together and of each alone, and the delay margin (module docstring).

    Parameters
    ----------
    Ad, Bd, K : ndarray
        As :func:`monodromy_with`: shapes (*b, N, n, n), (*b, N, n, m), (*b, N, m, n).
    h : float or ndarray, shape (*b,)
        The sample step of each loop, s.
    g_max : float
        The largest factor searched upward.
    tau_max : float
        The longest delay searched, s.
    xtol : float
        Tolerance on each margin, relative to its value (a factor; the delay, at least a
        sample).
    delay_xtol : float, optional
        The delay margin's own (default ``xtol``).
    block : int
        The gain margins' scan on the surrogate of blocks of that many steps first (1:
        none; :func:`gain_margins`).
    delay_guess : float, optional
        A guess of the delay margins, s (the level circle's for the tilted circles of
        its speed): the scan starts around it; the first crossing is still searched
        from 0.
    crossover_guess : float or ndarray, shape (*b,), optional
        A guess of the crossover, rad/s, which picks a periodic loop's
        (:func:`crossover_frequency`; the level circle's for the tilted ones).
    monodromy : ndarray, shape (*b, n, n), optional
        The loops' monodromies ``prod_k (A_k - B_k K_k)`` if at hand (the solver's), for
        their multipliers as they are (formed here without).

    Returns
    -------
    LoopMargins

    Examples
    --------
    The scalar loop of :func:`gain_margins` (a = 1.1, b k = 0.6): the factor's margins
    (0.1 / 0.6 and 2.1 / 0.6), which with one input are also that input's:

    >>> Ad, Bd, K = np.full((1, 4, 1, 1), 1.1), np.full((1, 4, 1, 1), 0.6), np.ones((1, 4, 1, 1))
    >>> lm = gs.loop_margins(Ad, Bd, K, 0.001)
    >>> np.round([lm.gain_down[0], lm.gain_up[0], lm.input_up[0, 0]], 4).tolist()
    [0.1667, 3.5, 3.5]
    """
    shape, (Ad, Bd, K) = _flat(Ad, Bd, K)
    m, n = Bd.shape[-1], Bd.shape[-2]
    masks, sign = _gain_kinds(m)
    s0 = (_nominal(Ad, Bd, K) if monodromy is None else
          _log_spectrum(np.reshape(monodromy, (-1, n, n)), np.zeros(Ad.shape[0])))
    p = _gain_crossings(Ad, Bd, K, masks, sign, g_max, s0, xtol, block)
    g = np.where(sign < 0, np.where(np.isinf(p), 0.0, 1.0 - p), 1.0 + p)
    h = np.broadcast_to(np.asarray(h, float), shape).reshape(-1)
    guess = None if delay_guess is None else np.full(h.shape, delay_guess) / h
    steps, phase = _delay_crossings(Ad, Bd, K, tau_max / h, s0,
                                    xtol if delay_xtol is None else delay_xtol, guess,
                                    _decay_steps(h))
    w = crossover_frequency(phase, Ad.shape[-3], h, None if crossover_guess is None else
                            np.broadcast_to(crossover_guess, shape).reshape(-1))
    per = g[:, 2:].reshape(-1, m, 2)
    return LoopMargins(g[:, 0].reshape(shape), g[:, 1].reshape(shape),
                       per[..., 0].reshape(shape + (m,)), per[..., 1].reshape(shape + (m,)),
                       (steps * h).reshape(shape), w.reshape(shape))
