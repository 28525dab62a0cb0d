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

Each margin is a root of ``rho(Phi(p)) - 1`` in the parameter p (g or tau), found for
every circle of a batch at once: a scan of the parameter on a grid (the first crossing,
which the nearest instability is) and bisection inside the bracket it finds (vectorised:
one monodromy product per step for the whole batch). Why by hand: python-control and
MATLAB's ``margin``/``diskmargin`` give these for time-invariant loops only; the periodic
loop's margins are those of its monodromy, which no library forms.
"""

from __future__ import annotations

import numpy as np

__all__ = ["monodromy_with", "spectral_radius", "gain_margins", "delay_margin", "G_MAX",
           "TAU_MAX_STEPS"]

#: the largest gain factor searched (+20 dB); no crossing below it: margin reported inf
G_MAX = 10.0
#: the longest extra delay searched, in samples of the period
TAU_MAX_STEPS = 8
#: the scan's points per bracket before the bisection
_SCAN = 48
#: bisection steps (2^-40 of the bracket)
_BISECT = 40


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


def _first_crossing(rho_of, lo, hi, n_batch):
    """The first p in [lo, hi] (arrays, per batch entry; searched from ``lo``) where
    ``rho_of(p) >= 1``, by a scan and bisection; inf where none (the loop stays stable
    over the whole range), NaN where already unstable at ``lo``."""
    lo, hi = np.broadcast_to(lo, n_batch).astype(float), np.broadcast_to(hi, n_batch).astype(float)
    s = np.linspace(0.0, 1.0, _SCAN + 1)
    P = lo[..., None] + (hi - lo)[..., None] * s  # (*b, S)
    R = rho_of(P)
    unstable = R >= 1.0
    first = np.argmax(unstable, axis=-1)
    found = unstable.any(-1)
    out = np.full(n_batch, np.inf)
    out[np.asarray(unstable[..., 0])] = np.nan
    todo = found & ~unstable[..., 0]
    if not todo.any():
        return out
    idx = np.where(todo, first, 1)
    a = np.take_along_axis(P, (idx - 1)[..., None], -1)[..., 0]
    b = np.take_along_axis(P, idx[..., None], -1)[..., 0]
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        bad = rho_of(m[..., None])[..., 0] >= 1.0
        a, b = np.where(bad, a, m), np.where(bad, m, b)
    out[todo] = 0.5 * (a + b)[todo]
    return out


def gain_margins(Ad, Bd, K, *, inputs=None, g_max: float = G_MAX):
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
    m = Bd.shape[-1]
    mask = np.zeros(m, bool)
    mask[list(range(m)) if inputs is None else list(inputs)] = True
    b = Ad.shape[:-3]

    def rho_of(G):  # G (*b, S): the factor on the chosen inputs
        gain = np.where(mask, G[..., None], 1.0)  # (*b, S, m)
        M = monodromy_with(Ad[..., None, :, :, :], Bd[..., None, :, :, :],
                           K[..., None, :, :, :], gain)
        return spectral_radius(M)

    up = _first_crossing(rho_of, 1.0, g_max, b)
    down_from_1 = _first_crossing(lambda G: rho_of(1.0 - G), 0.0, 1.0, b)  # 1 - g from 0
    down = np.where(np.isinf(down_from_1), 0.0, 1.0 - down_from_1)
    return down, up


def _delayed_monodromy(Ad, Bd, K, tau_steps):
    """The monodromy of the loop with the commands delayed by ``tau_steps`` samples
    (array (*b, S)), on the state ``[x, u_{k-1}, .., u_{k-D}]`` (module docstring)."""
    n, m = Ad.shape[-1], Bd.shape[-1]
    tau = np.asarray(tau_steps, float)
    D = int(np.ceil(np.max(tau))) + 1
    d = np.floor(tau).astype(int)
    f = tau - d
    na = n + D * m
    batch = np.broadcast_shapes(Ad.shape[:-3], tau.shape)
    M = np.broadcast_to(np.eye(na), batch + (na, na)).copy()
    # weights of the held commands u_{k-j}, j = 0..D, on the applied input
    j = np.arange(D + 1)
    w = (np.where(j == d[..., None], 1.0 - f[..., None], 0.0)
         + np.where(j == d[..., None] + 1, f[..., None], 0.0))  # (*batch, D + 1)
    for k in range(Ad.shape[-3]):
        A, B, Kk = Ad[..., k, :, :], Bd[..., k, :, :], K[..., k, :, :]
        T = np.zeros(batch + (na, na))
        # applied = w0 u_k + sum_{j>=1} w_j u_{k-j}, u_k = -K x
        T[..., :n, :n] = A - w[..., 0, None, None] * (B @ Kk)
        for jj in range(1, D + 1):
            cols = slice(n + (jj - 1) * m, n + jj * m)
            T[..., :n, cols] = w[..., jj, None, None] * B
        T[..., n:n + m, :n] = -Kk  # the register: u_k enters, the rest shift down
        for jj in range(1, D):
            T[..., n + jj * m:n + (jj + 1) * m, n + (jj - 1) * m:n + jj * m] = np.eye(m)
        M = T @ M
    return M


def delay_margin(Ad, Bd, K, h, *, tau_max_steps: float = TAU_MAX_STEPS):
    """The delay margin of periodic closed loops: the extra delay on the commands, s, at
    which a Floquet multiplier first reaches the unit circle.

    Parameters
    ----------
    Ad, Bd, K : ndarray
        As :func:`monodromy_with`.
    h : float or ndarray, shape (*b,)
        The sample step of each loop's period (its period over N), s.
    tau_max_steps : float
        The longest delay searched, in samples.

    Returns
    -------
    ndarray, shape (*b,)
        The margin, s (inf: stable up to ``tau_max_steps`` samples; NaN: unstable as it
        is).

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
    b = Ad.shape[:-3]

    def rho_of(T):  # T (*b, S) delays in samples
        return spectral_radius(_delayed_monodromy(Ad[..., None, :, :, :],
                                                  Bd[..., None, :, :, :],
                                                  K[..., None, :, :, :], T))

    steps = _first_crossing(rho_of, 0.0, tau_max_steps, b)
    return steps * np.broadcast_to(np.asarray(h, float), b)
