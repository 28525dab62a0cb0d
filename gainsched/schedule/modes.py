"""The closed loop's slowest modes per circle: Floquet time constants, frequencies, shapes.

The spectral radius of the monodromy says whether a circle's closed loop is stable, not
how slow it is: 0.993 per period at 15 m/s is a 97 s time constant. A periodic linear
loop ``x_{k+1} = (A_k - B_k K_k) x_k`` over one period ``T`` (``N`` steps) maps
``x_N = Phi x_0`` with the monodromy ``Phi = prod_k (A_k - B_k K_k)``; each eigenpair
``(lambda, v)`` of ``Phi`` is a Floquet mode (Bittanti & Colaneri, *Periodic Systems:
Filtering and Control*, Springer 2009, ch. 1): sampled once per period it evolves as
``lambda^j v``, so it decays with the time constant

    tau = -T / ln|lambda|                                   (s; negative: it grows)

and turns by ``arg lambda`` per period. A time-invariant loop (the tilt-0 circle solved
by the DARE) is the case ``N = 1``, ``T = dt``, ``Phi = A - B K``; there the frequency
``|arg lambda| / dt`` is the mode's own. For a periodic loop the Floquet exponent's
imaginary part is defined only modulo ``2 pi / T`` (the mode also carries the period's
own harmonics), so the frequency reported is the principal value ``|arg lambda| / T``,
the smallest consistent with ``lambda``. Damping ratio ``zeta = -ln|lambda| / |ln lambda|``
(1 for a real mode); from the principal value it is an upper bound on a periodic loop.
The time constant is exact in both cases.

A complex-conjugate pair is one mode (its member with ``Im lambda >= 0``). The shape is
``|v|`` in the states' own units (rad, rad/s, rad s for integrals, N for motor states),
scaled to a largest entry of 1: the states a mode lives in are those near 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MODE_COUNT", "DOMINANT", "FloquetModes", "floquet_modes", "dominant_states"]

#: modes kept per circle, slowest first (a complex pair counts once)
MODE_COUNT = 4
#: a state is dominant in a mode where its shape entry is at least this (largest = 1)
DOMINANT = 0.5


@dataclass(frozen=True)
class FloquetModes:
    """The slowest closed-loop modes of a batch of circles (batch shape ``b``), slowest first.

    Attributes
    ----------
    tau : ndarray, shape (*b, M)
        Time constant ``-T / ln|lambda|``, s (negative: the mode grows).
    frequency : ndarray, shape (*b, M)
        ``|arg lambda| / T``, rad/s: 0 for a real positive eigenvalue; for a periodic loop
        the principal value (module docstring).
    damping : ndarray, shape (*b, M)
        Damping ratio ``-ln|lambda| / |ln lambda|`` (1 for a real positive eigenvalue).
    shape : ndarray, shape (*b, M, n)
        ``|v|`` in the states' units, largest entry 1.
    """

    tau: np.ndarray
    frequency: np.ndarray
    damping: np.ndarray
    shape: np.ndarray


def floquet_modes(Phi, period_s, count: int = MODE_COUNT) -> FloquetModes:
    """The ``count`` slowest modes of closed-loop period maps, slowest first.

    Parameters
    ----------
    Phi : ndarray, shape (*b, n, n)
        Closed-loop state transition over one period: the monodromy ``prod_k (A_k - B_k
        K_k)``, or ``A - B K`` of a time-invariant loop (then ``period_s`` is its step).
    period_s : float or ndarray, shape (*b,)
        The period ``T`` the map spans, s.
    count : int
        Modes to keep (a complex pair counts once); at most the number of distinct modes.

    Returns
    -------
    FloquetModes
        Arrays with the batch shape of ``Phi`` and a trailing mode axis of ``count``.
    """
    Phi = np.asarray(Phi, dtype=float)
    lam, V = np.linalg.eig(Phi)  # (*b, n), (*b, n, n): columns are eigenvectors
    # one member of each conjugate pair: drop Im < 0 (a real eigenvalue has Im == 0 exactly)
    keep = lam.imag >= 0
    mag = np.abs(lam)
    # slowest first: largest |lambda|; excluded members sort last. A stable sort on the
    # magnitude alone keeps LAPACK's order among equal ones (deterministic on pinned BLAS).
    order = np.argsort(np.where(keep, -mag, np.inf), axis=-1, kind="stable")[..., :count]
    lam = np.take_along_axis(lam, order, axis=-1)
    V = np.take_along_axis(V, order[..., None, :], axis=-1)
    T = np.asarray(period_s, dtype=float)[..., None]
    with np.errstate(divide="ignore"):
        log_mag = np.log(np.abs(lam))
    angle = np.abs(np.angle(lam))
    shape = np.abs(np.swapaxes(V, -1, -2))  # (*b, count, n)
    shape = shape / shape.max(axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return FloquetModes(
            tau=-T / log_mag,
            frequency=angle / T,
            damping=-log_mag / np.hypot(log_mag, angle),
            shape=shape,
        )


def dominant_states(shape, names, threshold: float = DOMINANT) -> list[str]:
    """The states a mode lives in: names whose shape entry is at least ``threshold``.

    Parameters
    ----------
    shape : ndarray, shape (n,)
        A mode's shape (:attr:`FloquetModes.shape`, largest entry 1).
    names : sequence of str, length n
        The state names (``Table.state_names``).
    threshold : float
        Smallest entry counted, of the largest (1).

    Returns
    -------
    list of str
        Largest entry first.
    """
    shape = np.asarray(shape)
    order = np.argsort(-shape, kind="stable")
    return [names[i] for i in order if shape[i] >= threshold]
