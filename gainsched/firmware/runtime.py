"""Python reference of the C runtime (``gainsched/firmware/c/gainsched_runtime.c``), vectorised.

Same data, same semantics, same status bits as the firmware lookup; the tests
hold the two together on random queries (docs/runtime.md has the contract):

1. NaN/inf or out-of-limit inputs -> ``BAD_INPUT``, outputs zero.
2. S1: ``alpha < 0`` -> ``xi += pi``, ``alpha = -alpha``.
3. S2: ``xi_dot < 0`` -> ``xi = pi - xi``, ``xi_dot = -xi_dot``; outputs mapped
   back with ``K -> P_u K P_x``, ``u_d -> P_u u_d``, ``phi_d -> -phi_d``.
4. xi wrapped onto the periodic uniform axis; xi_dot and alpha clamped into the
   table (``CLAMPED_SPEED``, ``CLAMPED_TILT``).
5. Trilinear interpolation on the 8 corners of the cell (cell fractions within
   ``SNAP`` = 2^-12 of 0 or 1 are snapped onto the grid plane); ``INFEASIBLE`` if
   a corner with non-zero weight is marked infeasible, plus ``NO_GAINS`` (outputs
   zero) if such a corner has no gains.

Queries are rounded to float32 and every operation that picks the cell is
done in float32 in the C order, so the cell and the status flags are exactly
the C runtime's; the interpolation itself runs in float64 on the float32
table data (the numbers the firmware holds): :mod:`gainsched.firmware.dense`, whose names
this module re-exports.
"""

from __future__ import annotations

import dataclasses
from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from .. import constants
from ..constants import MASK_NO_GAINS
from .dense import (
    DESCRIPTOR_CHUNKS,
    VEHICLE_FIELDS,
    RuntimeData,
    VehicleConstants,
    c_identifier,
    crc32_of,
    runtime_data,
    vehicle_fields,
)

__all__ = [
    "OK",
    "CLAMPED_SPEED",
    "CLAMPED_TILT",
    "INFEASIBLE",
    "NO_GAINS",
    "BAD_INPUT",
    "BAD_ARG",
    "BAD_TABLE",
    "LOW_TENSION",
    "UNUSABLE",
    "MASK_NO_GAINS",
    "DESCRIPTOR_CHUNKS",
    "STATUS_NAMES",
    "status_text",
    "RuntimeData",
    "runtime_data",
    "VEHICLE_FIELDS",
    "VehicleConstants",
    "vehicle_fields",
    "Lookup",
    "Interpolator",
    "Domain",
    "fundamental_domain",
    "attitude_offsets",
    "map_back",
    "crc32_of",
    "c_identifier",
]

# status bits (gainsched_runtime.h)
OK = 0x00
CLAMPED_SPEED = 0x01
CLAMPED_TILT = 0x02
INFEASIBLE = 0x04
NO_GAINS = 0x08
BAD_INPUT = 0x10
BAD_ARG = 0x20
BAD_TABLE = 0x40
LOW_TENSION = 0x80  # the feed-forward's nominal tension is below the table's margin
UNUSABLE = NO_GAINS | BAD_INPUT | BAD_ARG
STATUS_NAMES = {
    CLAMPED_SPEED: "CLAMPED_SPEED",
    CLAMPED_TILT: "CLAMPED_TILT",
    INFEASIBLE: "INFEASIBLE",
    NO_GAINS: "NO_GAINS",
    BAD_INPUT: "BAD_INPUT",
    BAD_ARG: "BAD_ARG",
    BAD_TABLE: "BAD_TABLE",
    LOW_TENSION: "LOW_TENSION",
}

F32 = np.float32
PI_F = F32(np.pi)
XI_LIMIT = F32(constants.XI_LIMIT)  # rad
XI_DOT_LIMIT = F32(constants.XI_DOT_LIMIT)  # rad/s
TILT_LIMIT = F32(constants.TILT_LIMIT)  # rad
XI_DERIV_LIMIT = F32(1.0e6)  # |xi''|, |xi'''|, |xi''''| of gs_lookup_nominal (GS_XI_DERIV_LIMIT)
SNAP = F32(2.0**-12)  # cell fractions this close to 0 or 1 are put on the grid plane


def _snap(f):
    """``gs_snap``: fractions within SNAP of 0 or 1 become exactly 0 or 1 (float32)."""
    f = np.asarray(f, dtype=np.float32)
    return np.where(f < SNAP, F32(0), np.where(f > F32(1) - SNAP, F32(1), f)).astype(np.float32)


def _bracket(axis, v):
    """Clamp ``v`` into a (non-periodic) axis and find its cell, as the C runtime does.

    Returns ``(i0, i1, frac, clamped)``: corner indices, float32 fraction (snapped),
    and where the value was clamped.
    """
    clamped = (v < axis[0]) | (v > axis[-1])
    v = np.clip(v, axis[0], axis[-1])
    n = axis.size
    if n == 1:
        zero = np.zeros(v.shape, dtype=np.int64)
        return zero, zero, np.zeros(v.shape, dtype=np.float32), clamped
    i0 = np.clip(np.searchsorted(axis, v, side="right") - 1, 0, n - 2)
    return i0, i0 + 1, _snap((v - axis[i0]) / (axis[i0 + 1] - axis[i0])), clamped


def status_text(status: int) -> str:
    """``"OK"`` or the names of the set bits joined by ``|``."""
    status = int(status)
    names = [name for bit, name in STATUS_NAMES.items() if status & bit]
    return "|".join(names) if names else "OK"


@dataclass(frozen=True)
class Domain:
    """Queries mapped into the table's fundamental domain, as the C runtime maps them
    (steps 1-4 of the module doc; float32, C order). Every array has shape (m,).

    Attributes
    ----------
    xi : float32, rad
        The azimuth after S1 (``+ pi``) and S2 (``pi - xi``), not wrapped.
    mirrored, shifted : bool
        S2 (``xi_dot < 0``) and S1 (``alpha < 0``) applied.
    bad : bool
        Non-finite or out-of-limit input (``BAD_INPUT``; mapped as zeros).
    status : uint8
        ``CLAMPED_SPEED`` and ``CLAMPED_TILT`` bits.
    speed_cell, tilt_cell : tuple
        ``(i0, i1, frac)`` on the xi_dot and tilt axes (:func:`_bracket`).
    """

    xi: np.ndarray
    mirrored: np.ndarray
    shifted: np.ndarray
    bad: np.ndarray
    status: np.ndarray
    speed_cell: tuple
    tilt_cell: tuple


def fundamental_domain(d, xi, xi_dot, alpha) -> Domain:
    """Map queries (broadcast together, flattened) into the fundamental domain of the
    table ``d`` (anything with float32 ``xi_dot`` and ``tilt`` axes): refuse bad input,
    apply S1 and S2, clamp and bracket xi_dot and alpha, exactly as ``gs_lookup``."""
    with np.errstate(over="ignore", invalid="ignore"):
        x = np.asarray(xi, dtype=np.float32)
        v = np.asarray(xi_dot, dtype=np.float32)
        a = np.asarray(alpha, dtype=np.float32)
    x, v, a = (q.reshape(-1) for q in np.broadcast_arrays(x, v, a))
    bad = ~(np.isfinite(x) & np.isfinite(v) & np.isfinite(a))
    bad |= (np.abs(np.where(bad, 0, x)) > XI_LIMIT) | (np.abs(np.where(bad, 0, v)) > XI_DOT_LIMIT)
    bad |= np.abs(np.where(bad, 0, a)) > TILT_LIMIT
    zero = F32(0)
    x, v, a = (np.where(bad, zero, q).astype(np.float32) for q in (x, v, a))
    # S1, S2 (float32, as in C)
    shifted = a < 0
    x = np.where(shifted, x + PI_F, x)
    a = np.where(shifted, -a, a)
    mirrored = v < 0
    x = np.where(mirrored, PI_F - x, x)
    v = np.where(mirrored, -v, v)
    status = np.zeros(x.shape, dtype=np.uint8)
    k0, k1, fv, cs = _bracket(d.xi_dot, v)
    status |= np.where(cs, CLAMPED_SPEED, 0).astype(np.uint8)
    i0, i1, fa, ct = _bracket(d.tilt, a)  # a >= 0 = tilt[0]: only the top can clamp
    status |= np.where(ct, CLAMPED_TILT, 0).astype(np.uint8)
    return Domain(x.astype(np.float32), mirrored, shifted, bad, status, (k0, k1, fv),
                  (i0, i1, fa))


def map_back(K, U, P, mirrored, status, perm, sign) -> None:
    """Outputs computed in the fundamental domain, in place, as ``gs_lookup`` returns
    them: mapped back through S2 where ``mirrored`` (``K -> P_u K P_x`` with ``P_x`` of
    ``perm`` and ``sign``, ``u_d -> P_u u_d``, ``phi_d -> -phi_d``; exact, any float
    type) and zero where ``status`` is unusable. ``K`` (m, 4, n), ``U`` (m, 4), ``P`` (m,)."""
    if np.any(mirrored):
        K[mirrored] = K[mirrored][:, ::-1, :][:, :, perm] * sign
        U[mirrored] = U[mirrored][:, ::-1]
        P[mirrored] = -P[mirrored]
    dead = (status & UNUSABLE) != 0
    K[dead], U[dead], P[dead] = 0.0, 0.0, 0.0


def _both_offsets(halves):
    """The attitude offsets of the table's halves as one :class:`RuntimeData`-like holder
    (``offsets`` (n_halves n_a, n_v, 2, 2 H + 1) or None): the mirror image's circles
    after the vehicle's, zeros for a half without."""
    d = halves[0]
    if len(halves) == 1 or all(h.offsets is None for h in halves):
        return d
    nb = max(h.offsets.shape[-1] for h in halves if h.offsets is not None)
    n_a, n_v = d.tilt.size, d.xi_dot.size

    def padded(h):
        out = np.zeros((n_a, n_v, 2, nb), dtype=np.float32)
        if h.offsets is not None:
            k = h.offsets.shape[-1] // 2  # [c0, a_1..a_H, b_1..b_H]: pad each half
            K = nb // 2
            out[..., : 1 + k] = h.offsets[..., : 1 + k]
            out[..., 1 + K : 1 + K + k] = h.offsets[..., 1 + k :]
        return out

    return dataclasses.replace(d, offsets=np.concatenate([padded(h) for h in halves]))


def attitude_offsets(d, xi, alpha, circles, weights, mirrored, status) -> np.ndarray:
    """The nominal's attitude offsets at queries (m,), from the cell's circles: ``(m, 4)``
    = theta rad, d theta / d xi, chi rad, d chi / d xi (zero without offsets or where
    unusable). ``circles`` (m, 4) flat (tilt, speed) indices and ``weights`` (m, 4) their
    bilinear weights; ``mirrored`` (m,) S2 applied; ``status`` (m,) the lookup's."""
    from ..schedule.offsets import mirrored_coefficients, series, shifted_coefficients

    xi = np.asarray(xi, dtype=np.float64).reshape(-1)
    if d.offsets is None:
        return np.zeros((xi.size, 4))
    nb = d.offsets.shape[-1]
    coef = np.einsum("mc,mcab->mab", weights,
                     d.offsets.reshape(-1, 2, nb)[circles].astype(float))
    shifted = np.broadcast_to(np.asarray(alpha, dtype=np.float32), xi.shape) < 0
    # back from the fundamental domain: S2 undone first, then S1 (the lookup's reverse)
    coef = np.where(mirrored[:, None, None], mirrored_coefficients(coef), coef)
    coef = np.where(shifted[:, None, None], shifted_coefficients(coef), coef)
    out = series(coef, xi)
    out[(status & UNUSABLE) != 0] = 0.0
    return out


@dataclass(frozen=True)
class Lookup:
    """The gains, nominal and status an Interpolator returns for an array of queries.

    ``S`` is the broadcast shape of the queries ``(xi, xi_dot, alpha)`` (``()`` for
    scalars); ``n`` the LQR state dimension (11 for configs/paper.toml). Where a query
    is unusable (``status`` has ``NO_GAINS`` or ``BAD_INPUT``) every output is zero,
    as in the C runtime.

    Attributes
    ----------
    K : ndarray, shape (*S, 4, n)
        Interpolated gains for ``u = u_d - K (x - x_d)``, N per state unit; rows T1..T4,
        columns in the table's ``state_names`` order.
    u_d : ndarray, shape (*S, 4)
        Nominal motor thrusts T1..T4, N.
    phi_d : ndarray, shape S
        Nominal roll, rad.
    status : ndarray of uint8, shape S
        The C runtime's status bits (``GS_*``): 0 = ``OK``; ``CLAMPED_SPEED`` (0x01) and
        ``CLAMPED_TILT`` (0x02): the query was outside the table and clamped onto it;
        ``INFEASIBLE`` (0x04): a cell corner is infeasible; ``NO_GAINS`` (0x08): such a
        corner has no gains; ``BAD_INPUT`` (0x10): a non-finite or out-of-limit query.
        :func:`status_text` names them.

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> xi = np.linspace(0, 2 * np.pi, 8, endpoint=False)       # rad
    >>> look = gs.Interpolator(table)(xi, 9.0 / 1.6, np.deg2rad(20))
    >>> look.K.shape, look.u_d.shape, look.phi_d.shape, look.status.shape
    ((8, 4, 11), (8, 4), (8,), (8,))
    """

    K: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
    status: np.ndarray


class Interpolator:
    """Look up gains and nominal in a table exactly as the C firmware runtime does.

    ``Interpolator(table)(xi, xi_dot, alpha)`` returns a :class:`Lookup` (gains ``K``,
    nominal thrusts ``u_d``, roll ``phi_d``, status bits) for arrays of queries; the
    Python reference of ``gs_lookup`` in ``gainsched_runtime.c`` (docs/runtime.md), held
    to it bit for bit on the cell and the status flags by the tests.

    Parameters
    ----------
    table : Table or RuntimeData
        A loaded table (:func:`gainsched.load_table`), converted to the runtime's float32
        form; or that form already (:func:`runtime_data`).

    Attributes
    ----------
    data : RuntimeData
        The table as the firmware holds it (float32, infeasible gains as zeros, mask).
    n : int
        LQR state dimension, the columns of ``K``.

    Methods
    -------
    __call__(xi, xi_dot, alpha, *, chunk=16384)
        Look up arrays of queries (broadcast together): azimuth ``xi`` (rad), azimuth rate
        ``xi_dot`` (rad/s, speed / (rho + L_e); negative: the reversed direction) and
        circle tilt ``alpha`` (rad, any sign). Returns a :class:`Lookup`. Alias
        ``lookup``.
    query(xi, xi_dot, alpha)
        One scalar query for control loops: ``(K (4, n), u_d (4,) N, phi_d rad, status
        int)``, the same numbers bit for bit, about 10x faster per call.
    attitude(xi, xi_dot, alpha)
        The nominal's pitch and yaw offsets and their slopes along xi, (m, 4).
    roll_slope(xi, xi_dot, alpha)
        Slope of the interpolated ``phi_d`` along xi, rad/rad.

    Raises
    ------
    InputError
        The table cannot be held in the runtime's float32 form (axes that collapse in
        float32, more than 4096 azimuths, a value that overflows float32 at a feasible
        point, a state map that is not a signed permutation).

    See Also
    --------
    status_text : The names of a status's bits.

    Notes
    -----
    A query goes through the steps of the C runtime: a non-finite or out-of-limit input
    gives ``BAD_INPUT`` and zero outputs; a negative tilt is mapped by S1 (``xi += pi``,
    ``alpha = -alpha``) and a negative ``xi_dot`` by S2 (``xi = pi - xi``; outputs mapped
    back with ``K -> P_u K P_x``, ``u_d -> P_u u_d``, ``phi_d -> -phi_d``;
    docs/symmetry.md); xi is wrapped onto the periodic axis, ``xi_dot`` and ``alpha``
    are clamped into the table (``CLAMPED_SPEED``, ``CLAMPED_TILT``); the outputs are
    interpolated trilinearly between the 8 corners of the cell (float32 cell selection,
    float64 arithmetic on the float32 table data). A corner with non-zero weight that
    is infeasible sets ``INFEASIBLE``; if it has no gains, also ``NO_GAINS`` and the
    outputs are zero.

    Examples
    --------
    Gains on the 20 deg circle at 9 m/s, at azimuth 0.5 rad:

    >>> table = gs.load_table("tables/paper.h5")
    >>> interp = gs.Interpolator(table)
    >>> r = float(table.attrs["radius_m"])             # rho + L_e, m
    >>> look = interp(0.5, 9.0 / r, np.deg2rad(20))    # xi rad, xi_dot rad/s, alpha rad
    >>> look.K.shape, int(look.status)
    ((4, 11), 0)
    >>> np.round(look.u_d, 3).tolist(), round(float(np.rad2deg(look.phi_d)), 1)  # N, deg
    ([1.528, 1.236, 1.581, 1.277], -34.9)

    The control law ``u = u_d - K (x - x_d)`` for a 5 deg roll error (state 4, ``phi``):

    >>> dx = np.zeros(interp.n)
    >>> dx[4] = np.deg2rad(5)
    >>> np.round(look.u_d - look.K @ dx, 3).tolist()    # motor thrusts, N
    [1.413, 1.006, 2.019, 1.453]

    One query at a time in a control loop, and what the status says off the table:

    >>> K, u_d, phi_d, status = interp.query(0.5, 9.0 / r, np.deg2rad(20))
    >>> bool(np.array_equal(K, look.K)), status
    (True, 0)
    >>> from gainsched.firmware.runtime import status_text
    >>> status_text(interp(0.5, 20.0 / r, 0.2).status)          # above 15 m/s: clamped
    'CLAMPED_SPEED'
    >>> status_text(interp(0.5, 1.3 / r, np.deg2rad(30)).status)  # slack tether
    'INFEASIBLE|NO_GAINS'
    """

    def __init__(self, table):
        d = table if isinstance(table, RuntimeData) else runtime_data(table)
        self.data = d
        n_a, n_v, n_xi, n = d.dims
        self.n = n
        # the regular grid's points, then (a vehicle that is not its own mirror image)
        # those of its image, which the mirrored queries read: point index + n_points
        halves = (d,) if d.reverse is None else (d, d.reverse)
        self._n_points = n_a * n_v * n_xi if d.reverse is not None else 0
        Kg = np.empty((len(halves), n_a, n_v, n_xi, 4 * n))
        for h, half in zip(Kg, halves, strict=True):
            h[0] = half.K_tilt0.reshape(n_v, half.n_xi_tilt0, 4 * n)  # broadcast when 1
            if n_a > 1:
                h[1:] = half.K.reshape(n_a - 1, n_v, n_xi, 4 * n)
        self._K = Kg.reshape(-1, 4 * n)
        self._U = np.concatenate([h.u_d.astype(np.float64).reshape(-1, 4) for h in halves])
        self._P = np.concatenate([h.phi_d.astype(np.float64).reshape(-1) for h in halves])
        self._mask = np.concatenate([h.mask.reshape(-1) for h in halves])
        self._offsets = _both_offsets(halves)
        self._perm = d.state_perm.astype(np.intp)
        self._sign = d.state_sign.astype(np.float64)
        # single-query path (:meth:`query`): the gains and u_d of a point in one row,
        # the axes as float32 scalars (arithmetic) and Python floats (bisect)
        self._KU = np.concatenate([self._K, self._U], axis=1)
        self._speed1 = (tuple(F32(v) for v in d.xi_dot), [float(v) for v in d.xi_dot])
        self._tilt1 = (tuple(F32(v) for v in d.tilt), [float(v) for v in d.tilt])
        self._mask1 = self._mask.tolist()

    def cells(self, xi, xi_dot, alpha):
        """The cell of each query, exactly as the C runtime picks it.

        Returns ``(points, weights, status, mirrored)``: flat regular-grid point
        indices (m, 8) and float32 weights (m, 8) of the corners (bit 2 tilt, bit 1
        speed, bit 0 xi), status (m,) uint8, mirrored (m,) bool. Queries are flattened.
        """
        d = self.data
        q = fundamental_domain(d, xi, xi_dot, alpha)
        x, mirrored, status = q.xi, q.mirrored, q.status
        (i0, i1, fa), (k0, k1, fv) = q.tilt_cell, q.speed_cell
        # xi: periodic axis in cell units
        n_a, n_v, n_xi, _ = d.dims
        tt = x * d.xi_scale
        fl = np.floor(tt)
        fx = _snap(tt - fl)
        j0 = np.mod(fl.astype(np.int64), n_xi)
        j1 = np.where(j0 + 1 == n_xi, 0, j0 + 1)
        one = F32(1)
        ia, iv, ix = (i0, i1), (k0, k1), (j0, j1)
        wa, wv, wx = (one - fa, fa), (one - fv, fv), (one - fx, fx)
        pts = np.empty(x.shape + (8,), dtype=np.int64)
        w = np.empty(x.shape + (8,), dtype=np.float32)
        for c in range(8):
            bt, bv, bx = (c >> 2) & 1, (c >> 1) & 1, c & 1
            pts[:, c] = (ia[bt] * n_v + iv[bv]) * n_xi + ix[bx]
            w[:, c] = wa[bt] * wv[bv] * wx[bx]
        if self._n_points:  # the mirrored queries read the mirror image's points
            pts += np.where(mirrored, self._n_points, 0)[:, None]
        # only corners with non-zero weight count
        m = np.bitwise_or.reduce(np.where(w != 0, self._mask[pts], 0), axis=1)
        status |= np.where(m != 0, INFEASIBLE, 0).astype(np.uint8)
        status |= np.where(m & MASK_NO_GAINS, NO_GAINS, 0).astype(np.uint8)
        status = np.where(q.bad, BAD_INPUT, status).astype(np.uint8)
        return pts, w, status, mirrored

    def __call__(self, xi, xi_dot, alpha, *, chunk: int = 16384) -> Lookup:
        """Look up gains for arrays of queries (broadcast together); see the module doc."""
        shape = np.broadcast_shapes(np.shape(xi), np.shape(xi_dot), np.shape(alpha))
        pts, w, status, mirrored = self.cells(xi, xi_dot, alpha)
        m, n = status.size, self.n
        K = np.empty((m, 4 * n))
        U = np.empty((m, 4))
        P = np.empty(m)
        # self._K holds the gains on the regular grid (tilt-0 rows repeated over xi)
        for s in range(0, m, chunk):
            sl = slice(s, s + chunk)
            p, wc = pts[sl], w[sl].astype(np.float64)
            K[sl] = np.einsum("mc,mce->me", wc, self._K[p])
            U[sl] = np.einsum("mc,mce->me", wc, self._U[p])
            P[sl] = np.einsum("mc,mc->m", wc, self._P[p])
        K = K.reshape(m, 4, n)
        map_back(K, U, P, mirrored, status, self._perm, self._sign)
        return Lookup(
            K.reshape(shape + (4, n)),
            U.reshape(shape + (4,)),
            P.reshape(shape),
            status.reshape(shape),
        )

    lookup = __call__

    def attitude(self, xi, xi_dot, alpha) -> np.ndarray:
        """The nominal's attitude offsets at queries (m,): ``(m, 4)`` = theta rad,
        d theta / d xi, chi rad, d chi / d xi (zero without offsets or where unusable).

        The offsets' Fourier coefficients are interpolated over the cell's four circles
        (the lookup's weights summed over the azimuth pair), mapped back through S2
        (theta keeps its sign, chi flips; ``xi -> pi - xi``) and S1 (``xi -> xi + pi``), and
        the series evaluated at the query's azimuth.
        """
        pts, w, status, mirrored = self.cells(xi, xi_dot, alpha)
        circ = pts[:, ::2] // self.data.xi.size  # (m, 4) flat (tilt, speed) circles
        wc = (w[:, ::2].astype(np.float64) + w[:, 1::2])  # (m, 4)
        return attitude_offsets(self._offsets, xi, alpha, circ, wc, mirrored, status)

    def roll_slope(self, xi, xi_dot, alpha) -> np.ndarray:
        """Slope along xi of the interpolated ``phi_d`` at queries (m,), rad/rad: the
        (tilt, speed) weights times the difference across the xi cell (the C runtime's
        ``dphi_dxi``); S2 (``phi -> -phi``, ``xi -> pi - xi``) leaves its sign."""
        pts, w, status, _ = self.cells(xi, xi_dot, alpha)
        w = w.astype(np.float64)
        P = self._P
        pair = (w[:, ::2] + w[:, 1::2]) * (P[pts[:, 1::2]] - P[pts[:, ::2]])
        out = pair.sum(-1) * float(self.data.xi_scale)
        return np.where((status & UNUSABLE) != 0, 0.0, out)

    def query(self, xi: float, xi_dot: float, alpha: float):
        """One query, for control loops: ``(K (4, n), u_d (4,) N, phi_d rad, status int)``.

        The same numbers, bit for bit, as ``self(xi, xi_dot, alpha)`` on scalars (same
        float32 cell selection in the C order, same float64 einsum), without the
        array machinery: ~10x faster per call. Queries the scalar path does not cover
        (non-finite, out of the input limits) go through :meth:`__call__`.
        """
        xf, vf, af = float(xi), float(xi_dot), float(alpha)
        if not (abs(xf) <= 1e4 and abs(vf) <= 1e3 and abs(af) <= 2.0):  # NaN fails too
            return self._query_slow(xi, xi_dot, alpha)
        x, v, a = F32(xf), F32(vf), F32(af)
        if abs(float(x)) > XI_LIMIT or abs(float(v)) > XI_DOT_LIMIT or abs(float(a)) > TILT_LIMIT:
            return self._query_slow(xi, xi_dot, alpha)
        d = self.data
        if a < 0:  # S1
            x = x + PI_F
            a = -a
        mirrored = bool(v < 0)
        if mirrored:  # S2
            x = PI_F - x
            v = -v
        n_xi = d.xi.size
        tt = x * d.xi_scale
        fl = np.floor(tt)
        fx = self._snap1(tt - fl)
        j0 = int(fl) % n_xi
        j1 = 0 if j0 + 1 == n_xi else j0 + 1
        status = 0
        k0, k1, fv, cs = self._bracket1(*self._speed1, v)
        i0, i1, fa, ct = self._bracket1(*self._tilt1, a)
        if cs:
            status |= CLAMPED_SPEED
        if ct:
            status |= CLAMPED_TILT
        one = F32(1)
        ia, iv, ix = (i0, i1), (k0, k1), (j0, j1)
        wa, wv, wx = (one - fa, fa), (one - fv, fv), (one - fx, fx)
        n_v = d.xi_dot.size
        base = self._n_points if mirrored else 0  # the mirror image's points, if any
        pts = [0] * 8
        w = [0.0] * 8
        m = 0
        for c in range(8):
            bt, bv, bx = (c >> 2) & 1, (c >> 1) & 1, c & 1
            p = base + (ia[bt] * n_v + iv[bv]) * n_xi + ix[bx]
            wc = wa[bt] * wv[bv] * wx[bx]
            pts[c], w[c] = p, float(wc)
            if wc != 0:
                m |= self._mask1[p]
        if m:
            status |= INFEASIBLE
        if m & MASK_NO_GAINS:
            status |= NO_GAINS
        n = self.n
        wq = np.array([w])
        row = np.einsum("mc,mce->me", wq, self._KU[pts][None])[0]
        K = row[: 4 * n].reshape(4, n)
        U = row[4 * n :]
        P = float(np.einsum("mc,mc->m", wq, self._P[pts][None])[0])
        if mirrored:
            # C order like __call__'s K: K @ x then takes the same BLAS path (same bits)
            K = np.ascontiguousarray(K[::-1, :][:, self._perm] * self._sign)
            U = U[::-1].copy()
            P = -P
        if status & UNUSABLE:
            return np.zeros((4, n)), np.zeros(4), 0.0, status
        return K, U, P, status

    def _query_slow(self, xi, xi_dot, alpha):
        r = self(xi, xi_dot, alpha)
        return r.K, r.u_d, float(r.phi_d), int(r.status)

    @staticmethod
    def _snap1(f):
        """:func:`_snap` of one float32 scalar."""
        if f < SNAP:
            return F32(0)
        if f > F32(1) - SNAP:
            return F32(1)
        return f

    @classmethod
    def _bracket1(cls, ax32, axf, v):
        """:func:`_bracket` of one float32 scalar; ``ax32``/``axf``: the axis as float32
        scalars and as Python floats."""
        clamped = bool(v < ax32[0] or v > ax32[-1])
        if v < ax32[0]:
            v = ax32[0]
        elif v > ax32[-1]:
            v = ax32[-1]
        n = len(axf)
        if n == 1:
            return 0, 0, F32(0), clamped
        i0 = min(max(bisect_right(axf, float(v)) - 1, 0), n - 2)
        return i0, i0 + 1, cls._snap1((v - ax32[i0]) / (ax32[i0 + 1] - ax32[i0])), clamped


# --------------------------------------------------------------------------- midpoint check
