"""Compact tables: per circle, the gains and nominal as Fourier series in the azimuth.

The dense table stores every value at ``n_xi`` azimuths of every (tilt, speed) circle
and interpolates linearly between them. The gains are smooth and periodic in the
azimuth, so a few harmonics hold them as well: the compact form stores, for each
feasible circle, the coefficients of the truncated Fourier series

``f(xi) = c_0 + sum_{k=1..H} a_k cos(k xi) + b_k sin(k xi)``

of every table value (the ``4 n`` gains, the 4 nominal thrusts, the nominal roll), with
the harmonic count ``H`` of that circle the smallest that meets a relative error bound
at the stored azimuths (:func:`compact_data`). Infeasible circles store nothing, a
level circle's constant values one coefficient each, and feasibility is one mask byte
per circle. docs/table-format.md, "The compact format", has the layout and the figures.

A lookup (:class:`CompactInterpolator`) takes the dense lookup's steps 1-4 (refuse bad
input, the symmetry maps S1 and S2, clamp and bracket speed and tilt:
:func:`~gainsched.firmware.runtime.fundamental_domain`), then evaluates the series of
the (up to) four circles around the query at its azimuth, weighted bilinearly over
tilt and speed, with one sine-cosine pair per lookup (:func:`sincos_f32`, the C
runtime's ``gs_sincosf``) and the angle-addition recurrence for the harmonics. Every
operation is float32, in the C runtime's order, so the reference and the C runtime
give the same bits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..constants import MASK_NO_GAINS
from ..errors import InputError
from .runtime import (
    BAD_INPUT,
    F32,
    INFEASIBLE,
    NO_GAINS,
    UNUSABLE,
    Lookup,
    RuntimeData,
    attitude_offsets,
    crc32_of,
    fundamental_domain,
    map_back,
)

__all__ = ["DEFAULT_AZIMUTH_ERROR", "MAX_HARMONICS", "FORMAT_COMPACT", "CompactData",
           "compact_data", "fit_harmonics", "sincos_f32", "CompactInterpolator"]

#: default bound on the relative error of the truncated series at the stored azimuths
#: (:func:`fit_harmonics`). Measured on the paper grid against gains solved directly at
#: the azimuth midpoints of its circles, the series at 1 % err by at most 1.03 %, linear
#: interpolation between the 36 samples by 1.20 %: as accurate as the dense table along
#: the azimuth, and more at every cell midpoint (1.67 % against 1.83 %), in 118 KB
DEFAULT_AZIMUTH_ERROR = 0.01
#: the nominal roll's error is taken relative to the circle's largest roll, but to no
#: less than this (rad): a level circle's small roll is not held to 1 % of itself
ROLL_FLOOR = 0.01
#: the nominal thrusts and roll are held to a quarter of the bound: their error is a
#: steady offset of the flight (a firmware flies u_d and phi_d as they are), where a gain
#: error only changes the loop a little; five series per circle, few bytes
NOMINAL_SHARE = 0.25
#: the most harmonics a value may take (``GS_MAX_HARMONICS``): a circle that needs more
#: is refused (its values change too fast along the azimuth for the grid's samples)
MAX_HARMONICS = 16
#: ``gs_table.format`` of a compact table (``GS_FORMAT_COMPACT``)
FORMAT_COMPACT = 1
#: the chunks of :meth:`CompactData.crc_chunks` that describe the table, not its data
COMPACT_DESCRIPTOR_CHUNKS = ("dims", "xi_scale", "format", "n_harmonics", "n_coef",
                             "offset_harmonics")


@dataclass(frozen=True)
class CompactData:
    """A table in the compact form, as the firmware holds it (float32).

    Attributes
    ----------
    base : RuntimeData
        The dense form it was made from: axes, state map, vehicle constants, attitude
        offsets and metadata are shared; its per-azimuth arrays are not stored.
    harmonics : ndarray of uint8, shape (n_a, n_v, n_value)
        Harmonic count ``H`` per circle and value (0 for an infeasible circle).
    start : ndarray of uint32, shape (n_a n_v,)
        Index in ``coef`` of each circle's first coefficient (infeasible circles: the
        next circle's).
    coef : ndarray of float32, shape (n_coef,)
        Per circle, per value, its ``2 H + 1`` coefficients: the mean, then the cosine
        and sine coefficients of harmonic 1, 2, ... The values: ``K`` (4 x n,
        row-major, N per state unit), ``u_d`` (4, N), ``phi_d`` (rad).
    mask : ndarray of uint8, shape (n_a, n_v)
        Per circle, the OR of its azimuths' reason bits, with ``MASK_NO_GAINS`` where
        any azimuth has no gains (a partly feasible circle has none in this form).
    fit_error : ndarray, shape (n_a, n_v)
        The largest relative error of the series at the stored azimuths
        (:func:`fit_harmonics`); NaN for a circle without gains.
    bound : float
        The bound the harmonic counts were chosen for.

    Examples
    --------
    >>> d = gs.load_table("tables/paper.h5")
    >>> form = gs.compact_data(gs.firmware.runtime.runtime_data(d))
    >>> form.nbytes(), form.n_value, form.n_harmonics   # bytes, series per circle, most H
    (121937, 49, 7)
    >>> len(form.series(2, 12)), form.series(2, 12)[0].size   # 20 deg, 9 m/s: K[0, 0]
    (49, 7)
    """

    base: RuntimeData
    harmonics: np.ndarray
    start: np.ndarray
    coef: np.ndarray
    mask: np.ndarray
    fit_error: np.ndarray
    bound: float

    @property
    def n_value(self) -> int:
        """Values per coefficient row: ``4 n + 4 + 1``."""
        return 4 * self.base.dims[3] + 5

    def series(self, i: int, j: int) -> list[np.ndarray]:
        """The coefficients of circle (tilt ``i``, speed ``j``): one array of ``2 H + 1``
        per value (an empty list for a circle without gains)."""
        if self.mask[i, j] & MASK_NO_GAINS:
            return []
        s = int(self.start[i * self.base.dims[1] + j])
        out = []
        for h in self.harmonics[i, j].astype(int):
            out.append(self.coef[s:s + 2 * h + 1])
            s += 2 * h + 1
        return out

    def __getattr__(self, key):
        """The dense form's axes, state map, vehicle constants, offsets and metadata
        (``xi_dot``, ``tilt``, ``vehicle``, ...) are the compact table's too."""
        if key.startswith("__") or key == "base":
            raise AttributeError(key)
        return getattr(self.base, key)

    @property
    def dims(self) -> tuple[int, int, int, int]:
        """``(n_tilt, n_speed, n_xi, n_state)``; ``n_xi``: the azimuth samples fitted."""
        return self.base.dims

    @property
    def n_harmonics(self) -> int:
        """The largest harmonic count of any series (``GS_MAX_HARMONICS`` at most)."""
        return int(self.harmonics.max(initial=0))

    def crc_chunks(self):
        """``(label, bytes)`` in the order ``gs_table_crc32`` reads a compact table: the
        dims, ``xi_scale``, the format and its sizes, the axes, the state map, the circle
        mask, the harmonic counts, the circles' first coefficients, the coefficients,
        then the vehicle and the attitude offsets as in the dense form."""
        b = self.base
        u32 = lambda *v: np.array(v, dtype="<u4").tobytes()  # noqa: E731
        yield "dims", u32(*b.dims)
        yield "xi_scale", np.array([b.xi_scale], dtype="<f4").tobytes()
        yield "format", u32(FORMAT_COMPACT)
        yield "n_harmonics", u32(self.n_harmonics)
        yield "n_coef", u32(self.coef.size)
        for key in ("xi", "speed", "xi_dot", "tilt", "state_sign"):
            yield key, np.ascontiguousarray(getattr(b, key), dtype="<f4").tobytes()
        yield "state_perm", np.ascontiguousarray(b.state_perm, dtype=np.uint8).tobytes()
        yield "mask", np.ascontiguousarray(self.mask, dtype=np.uint8).tobytes()
        yield "harmonics", np.ascontiguousarray(self.harmonics, dtype=np.uint8).tobytes()
        yield "coef_start", np.ascontiguousarray(self.start, dtype="<u4").tobytes()
        yield "coef", np.ascontiguousarray(self.coef, dtype="<f4").tobytes()
        for label, chunk in b.crc_chunks():
            if label in ("vehicle", "offset_harmonics", "offsets"):
                yield label, chunk

    def crc32(self) -> int:
        """CRC-32 (zlib, IEEE) of :meth:`crc_chunks`, as ``gs_table_crc32`` computes it."""
        return crc32_of(self.crc_chunks())

    def nbytes(self) -> int:
        """Bytes of table data the firmware stores (every array of :meth:`crc_chunks`,
        without the descriptor's sizes)."""
        return sum(len(c) for k, c in self.crc_chunks() if k not in COMPACT_DESCRIPTOR_CHUNKS)


def _unit_circle(n: int) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of ``2 pi m / n``, m = 0..n-1, from Python's libm one value at a time
    (numpy's vector sin/cos differ between SIMD families; these bits do not)."""
    ang = [2.0 * math.pi * m / n for m in range(n)]
    return np.array([math.cos(x) for x in ang]), np.array([math.sin(x) for x in ang])


def _dft(f: np.ndarray, h_max: int) -> np.ndarray:
    """Fourier coefficients of samples at ``xi_m = 2 pi m / N``: ``f (N, ...)`` ->
    ``(2 h_max + 1, ...)`` rows mean, cos 1, sin 1, cos 2, ... Written as a loop over the
    samples (one numpy add per sample and row) so that every sum is taken in the same
    order on every machine: the table's bits must not depend on the CPU."""
    n = f.shape[0]
    cos, sin = _unit_circle(n)
    out = np.zeros((2 * h_max + 1,) + f.shape[1:])
    for m in range(n):
        out[0] += f[m]
        for k in range(1, h_max + 1):
            out[2 * k - 1] += cos[(k * m) % n] * f[m]
            out[2 * k] += sin[(k * m) % n] * f[m]
    out[0] /= n
    out[1:] *= 2.0 / n
    return out


def _sum0(x: np.ndarray) -> np.ndarray:
    """Sum over the first axis, one numpy add per slice: the same order on every machine
    (a reduction over the last axis is vectorised differently by different CPUs)."""
    out = x[0].copy()
    for row in x[1:]:
        out += row
    return out


def fit_harmonics(f: np.ndarray, n: int, bound: float,
                  max_harmonics: int = MAX_HARMONICS) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray]:
    """Truncated Fourier series of circles' values, each value with the fewest harmonics
    that keep its circle within ``bound`` at the samples.

    The criteria, at every sample azimuth of a circle: the gain error's Frobenius norm
    relative to the gain matrix's (what ``gainsched check`` measures) within ``bound``;
    each nominal thrust's error relative to the circle's largest nominal thrust, and the
    roll's relative to the circle's largest roll (at least :data:`ROLL_FLOOR`), within
    ``NOMINAL_SHARE * bound``. The thrusts and the roll each get the fewest harmonics
    that meet their own criterion; the gains
    share theirs greedily: one harmonic more, each step, for the gain whose remaining
    error weighs most (its squared residual summed over the samples, each relative to
    the squared gain norm there), until the circle meets the bound. Every sum is taken in
    a fixed order, so the counts are the same on every machine.

    Parameters
    ----------
    f : ndarray, shape (N, C, 4 n + 5)
        The values of C circles at the N azimuths ``2 pi m / N`` (gains, N per state
        unit; nominal thrusts, N; nominal roll, rad), all finite.
    n : int
        LQR state dimension.
    bound : float
        Relative error bound, e.g. 0.005.
    max_harmonics : int, default :data:`MAX_HARMONICS`
        The most harmonics a value may take (and at most ``(N - 1) // 2``).

    Returns
    -------
    harmonics : ndarray of int, shape (C, 4 n + 5)
        Harmonic count per circle and value.
    coef : ndarray, shape (2 H_top + 1, C, 4 n + 5)
        The coefficients of every harmonic up to ``H_top = min(max_harmonics,
        (N - 1) // 2)``: rows mean, cos 1, sin 1, cos 2, ... (rows beyond a value's own
        count are not part of its series).
    error : ndarray, shape (C,)
        Each circle's error at the samples as a share of its bound (the gains' relative
        error; the thrusts' and roll's over ``NOMINAL_SHARE``), the largest of the
        three; above ``bound`` only where ``H_top`` harmonics do not meet it.
    """
    N, C, V = f.shape
    nk = 4 * n
    h_top = min(max_harmonics, (N - 1) // 2)
    coef = _dft(f, h_top)
    cos, sin = _unit_circle(N)
    m = np.arange(N)
    res = f - coef[0]  # (N, C, V): the residual of each value's series so far
    H = np.zeros((C, V), dtype=np.int64)
    k_norm2 = _sum0(np.moveaxis(f[..., :nk] ** 2, -1, 0))  # (N, C)
    scale = np.concatenate([np.broadcast_to(np.abs(f[..., nk:nk + 4]).max((0, 2))[:, None],
                                            (C, 4)),
                            np.maximum(np.abs(f[..., -1]).max(0), ROLL_FLOOR)[:, None]], 1)
    cols = np.arange(C)

    def add_harmonic(c, e):
        """One harmonic more for values ``e`` of circles ``c`` (index arrays)."""
        k = H[c, e] + 1
        H[c, e] = k
        res[:, c, e] -= cos[(k[None] * m[:, None]) % N] * coef[2 * k - 1, c, e]
        res[:, c, e] -= sin[(k[None] * m[:, None]) % N] * coef[2 * k, c, e]

    while True:
        rel2 = res[..., :nk] ** 2 / k_norm2[..., None]  # (N, C, nk)
        gain_err2 = _sum0(np.moveaxis(rel2, -1, 0)).max(0)  # (C,)
        other = np.abs(res[..., nk:]).max(0) / (scale * NOMINAL_SHARE)  # (C, 5)
        over_k = (gain_err2 > bound * bound) & np.any(H[:, :nk] < h_top, axis=1)
        over_o = (other > bound) & (H[:, nk:] < h_top)
        if not (over_k.any() or over_o.any()):
            break
        if over_k.any():
            weight = _sum0(rel2)  # (C, nk)
            weight[H[:, :nk] >= h_top] = -1.0
            c = cols[over_k]
            add_harmonic(c, np.argmax(weight[c], axis=1))
        if over_o.any():
            c, e = np.nonzero(over_o)
            add_harmonic(c, e + nk)
    rel2 = res[..., :nk] ** 2 / k_norm2[..., None]
    error = np.maximum(np.sqrt(_sum0(np.moveaxis(rel2, -1, 0)).max(0)),
                       (np.abs(res[..., nk:]).max(0) / (scale * NOMINAL_SHARE)).max(1))
    return H, coef, error


def _circle_values(d: RuntimeData) -> np.ndarray:
    """Every table value per circle and azimuth: (n_xi, n_a n_v, 4 n + 5) float64."""
    n_a, n_v, n_xi, n = d.dims
    K = np.empty((n_a, n_v, n_xi, 4 * n))
    K[0] = d.K_tilt0.reshape(n_v, d.n_xi_tilt0, 4 * n)
    if n_a > 1:
        K[1:] = d.K.reshape(n_a - 1, n_v, n_xi, 4 * n)
    vals = np.concatenate([K, d.u_d.reshape(n_a, n_v, n_xi, 4),
                           d.phi_d.reshape(n_a, n_v, n_xi, 1)], axis=-1)
    return np.moveaxis(vals.reshape(n_a * n_v, n_xi, -1), 1, 0).astype(np.float64)


def compact_data(d: RuntimeData, bound: float = DEFAULT_AZIMUTH_ERROR, *,
                 source: str | None = None, key: str = "firmware.azimuth_error") -> CompactData:
    """The compact form of a dense runtime table.

    Parameters
    ----------
    d : RuntimeData
        The dense form (:func:`~gainsched.firmware.runtime.runtime_data`).
    bound : float, default :data:`DEFAULT_AZIMUTH_ERROR`
        Relative error the series must meet at the stored azimuths, per circle
        (:func:`fit_harmonics`).
    source, key : str, optional
        Where the bound came from, for the error message (default: the table's name and
        the config key ``firmware.azimuth_error``).

    Returns
    -------
    CompactData
        The series per circle and value, their harmonic counts, the circle mask.

    Raises
    ------
    InputError
        A feasible circle that :data:`MAX_HARMONICS` harmonics do not fit within the
        bound (its values change too fast along the azimuth for the samples), naming
        the circle. A table of both flight directions (``d.reverse``): naming
        ``firmware.format`` (the compact format holds one).

    Examples
    --------
    The paper table at two bounds (table data, bytes):

    >>> from gainsched.firmware.runtime import runtime_data
    >>> dense = runtime_data(gs.load_table("tables/paper.h5"))
    >>> dense.nbytes(), gs.compact_data(dense).nbytes(), gs.compact_data(dense, 0.005).nbytes()
    (834147, 121937, 139065)
    """
    if d.reverse is not None:  # both flight directions: the C runtime reads them dense
        raise InputError(d.name if source is None else source, "firmware.format",
                         "\"compact\" holds one flight direction; this table holds both (the "
                         "vehicle is not its own mirror image, docs/symmetry.md): use \"dense\"")
    n_a, n_v, n_xi, n = d.dims
    n_value = 4 * n + 5
    mask = np.bitwise_or.reduce(d.mask.reshape(n_a, n_v, n_xi), axis=-1)
    good = (mask.reshape(-1) & MASK_NO_GAINS) == 0
    harmonics = np.zeros((n_a * n_v, n_value), dtype=np.int64)
    fit_error = np.full(n_a * n_v, np.nan)
    blocks = []
    if np.any(good):
        H, coef, err = fit_harmonics(_circle_values(d)[:, good], n, bound)
        harmonics[good], fit_error[good] = H, err
        if np.any(err > bound):
            c = int(np.flatnonzero(good)[np.argmax(err)])
            i, j = divmod(c, n_v)
            raise InputError(d.name if source is None else source, key,
                             f"{100 * bound:g} % not met at speed {float(d.speed[j]):g} m/s, "
                             f"tilt {math.degrees(float(d.tilt[i])):g} deg: "
                             f"{100 * err.max():.3g} % with "
                             f"{int(H.max())} harmonics; raise grid.azimuth_samples")
        for b, h in enumerate(H):  # value-major: each value's 2 H + 1 coefficients
            blocks += [coef[:2 * he + 1, b, e] for e, he in enumerate(h)]
    sizes = np.where(good[:, None], 2 * harmonics + 1, 0).sum(1)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32)
    flat = np.concatenate(blocks) if blocks else np.zeros(0)
    return CompactData(d, harmonics.reshape(n_a, n_v, n_value).astype(np.uint8), start,
                       flat.astype(np.float32), mask.astype(np.uint8),
                       fit_error.reshape(n_a, n_v), float(bound))


# float32 constants of gs_sincosf (gainsched_runtime.c): pi/2 in three parts, 2/pi, and the
# Cephes minimax coefficients of sin and cos on [-pi/4, pi/4]
_PIO2 = tuple(F32(float.fromhex(h)) for h in ("0x1.92p+0", "0x1.fb4p-12", "0x1.4442d2p-24"))
_2_OVER_PI = F32(float.fromhex("0x1.45f306p-1"))
_SIN = tuple(F32(float.fromhex(h)) for h in ("-0x1.555546p-3", "0x1.11073cp-7", "-0x1.9943f2p-13"))
_COS = tuple(F32(float.fromhex(h)) for h in ("0x1.55554ap-5", "-0x1.6c0c34p-10", "0x1.99eb9cp-16"))


def sincos_f32(x) -> tuple[np.ndarray, np.ndarray]:
    """``gs_sincosf`` of the C runtime, bit for bit: sine and cosine of float32 ``x``
    (rad, ``|x| <= 1e4``) from a three-part pi/2 reduction and Cephes' minimax
    polynomials, every operation in float32 and in the C order."""
    x = np.asarray(x, dtype=np.float32)
    ax = np.abs(x)
    k = (ax * _2_OVER_PI + F32(0.5)).astype(np.int32)  # truncation, as the C cast
    kf = k.astype(np.float32)
    r = ((ax - kf * _PIO2[0]) - kf * _PIO2[1]) - kf * _PIO2[2]
    z = r * r
    sr = r + r * z * (_SIN[0] + z * (_SIN[1] + z * _SIN[2]))
    cr = (F32(1) - F32(0.5) * z) + z * z * (_COS[0] + z * (_COS[1] + z * _COS[2]))
    q = k & 3
    sv = np.select([q == 0, q == 1, q == 2], [sr, cr, -sr], -cr).astype(np.float32)
    cv = np.select([q == 0, q == 1, q == 2], [cr, -sr, -cr], sr).astype(np.float32)
    return np.where(x < 0, -sv, sv).astype(np.float32), cv


class CompactInterpolator:
    """Look up gains and nominal in a compact table exactly as the C runtime does.

    The compact counterpart of :class:`~gainsched.firmware.runtime.Interpolator`: same
    queries, same :class:`~gainsched.firmware.runtime.Lookup`, same status bits (with the
    circle's mask in place of the azimuth samples'), computed in float32 in the C
    runtime's order (bit for bit what ``gs_lookup`` returns for a compact table).

    Parameters
    ----------
    data : CompactData
        The table (:func:`compact_data`).

    Attributes
    ----------
    data : CompactData
        The table.
    n : int
        LQR state dimension, the columns of ``K``.

    Examples
    --------
    The compact and the dense lookup at 9 m/s on the 20 deg circle:

    >>> from gainsched.firmware.runtime import runtime_data
    >>> dense = runtime_data(gs.load_table("tables/paper.h5"))
    >>> compact = gs.CompactInterpolator(gs.compact_data(dense))
    >>> a, b = compact(0.5, 9.0 / 1.6, np.deg2rad(20)), gs.Interpolator(dense)(0.5, 9.0 / 1.6,
    ...                                                                       np.deg2rad(20))
    >>> int(a.status), bool(np.linalg.norm(a.K - b.K) / np.linalg.norm(b.K) < 0.01)
    (0, True)
    """

    def __init__(self, data: CompactData):
        self.data = data
        n_a, n_v, _, n = data.base.dims
        self.n = n
        n_c, n_value = n_a * n_v, data.n_value
        # per circle and value, the coefficient count (0: a circle without gains)
        good = (data.mask.reshape(-1) & MASK_NO_GAINS) == 0
        self._rows = np.where(good[:, None], 2 * data.harmonics.reshape(n_c, n_value).astype(
            np.int64) + 1, 0)
        self._top = int(self._rows.max(initial=1))
        # the coefficients on a regular (circle, row, value) array, zero past a value's
        # own rows: vectorised evaluation; rows a value lacks are skipped, not added
        pad = np.zeros((n_c, self._top, n_value), dtype=np.float32)
        for c in np.flatnonzero(good):
            for e, series in enumerate(data.series(*divmod(int(c), n_v))):
                pad[c, :series.size, e] = series
        self._coef = pad
        self._mask = data.mask.reshape(-1)
        self._perm = data.base.state_perm.astype(np.intp)
        self._sign = data.base.state_sign

    def __call__(self, xi, xi_dot, alpha, *, chunk: int = 16384) -> Lookup:
        """Look up arrays of queries (broadcast together): azimuth ``xi`` (rad), azimuth
        rate ``xi_dot`` (rad/s) and tilt ``alpha`` (rad); returns a :class:`Lookup`."""
        shape = np.broadcast_shapes(np.shape(xi), np.shape(xi_dot), np.shape(alpha))
        q = fundamental_domain(self.data.base, xi, xi_dot, alpha)
        m, n = q.xi.size, self.n
        out = np.empty((m, self.data.n_value), dtype=np.float32)
        status = np.empty(m, dtype=np.uint8)
        for s in range(0, m, chunk):
            sl = slice(s, s + chunk)
            out[sl], status[sl] = self._evaluate(q, sl)
        K = out[:, :4 * n].reshape(m, 4, n)
        U = out[:, 4 * n:4 * n + 4]
        P = out[:, -1]
        map_back(K, U, P, q.mirrored, status, self._perm, self._sign)  # exact in float32
        return Lookup(K.astype(np.float64).reshape(shape + (4, n)),
                      U.astype(np.float64).reshape(shape + (4,)),
                      P.astype(np.float64).reshape(shape), status.reshape(shape))

    lookup = __call__

    def query(self, xi: float, xi_dot: float, alpha: float):
        """One query: ``(K (4, n), u_d (4,) N, phi_d rad, status int)``, the numbers of
        ``self(xi, xi_dot, alpha)``."""
        r = self(xi, xi_dot, alpha)
        return r.K, r.u_d, float(r.phi_d), int(r.status)

    def roll_slope(self, xi, xi_dot, alpha) -> np.ndarray:
        """Slope along xi of the nominal roll at queries (m,), rad/rad: the derivative of
        the cell's roll series at the query's azimuth (the C runtime's ``dphi_dxi``; S1
        and S2 leave its sign), float64; zero where unusable."""
        q = fundamental_domain(self.data.base, xi, xi_dot, alpha)
        weights, circles, status = self._cell(q, slice(None))
        x = q.xi.astype(np.float64)
        out = np.zeros(x.size)
        roll = self.data.n_value - 1
        k = np.arange(1, (self._top - 1) // 2 + 1)
        for w, c in zip(weights, circles, strict=True):
            cf = self._coef[c, :, roll].astype(np.float64)  # (m, rows), zero past H
            a, b = cf[:, 1::2], cf[:, 2::2]
            d = (k * (b * np.cos(np.outer(x, k)) - a * np.sin(np.outer(x, k)))).sum(1)
            out += np.where(w != 0, w.astype(np.float64) * d, 0.0)
        return np.where((status & UNUSABLE) != 0, 0.0, out)

    def attitude(self, xi, xi_dot, alpha) -> np.ndarray:
        """The nominal's attitude offsets at queries (m,): ``(m, 4)`` = theta rad,
        d theta / d xi, chi rad, d chi / d xi, as the dense lookup's
        (:func:`~gainsched.firmware.runtime.attitude_offsets`)."""
        q = fundamental_domain(self.data.base, xi, xi_dot, alpha)
        weights, circles, status = self._cell(q, slice(None))
        return attitude_offsets(self.data.base, xi, alpha, np.stack(circles, 1),
                                np.stack(weights, 1).astype(np.float64), q.mirrored, status)

    def _cell(self, q, sl):
        """The (tilt, speed) cell of the queries ``sl`` of ``q``: four weights (m,)
        float32 and four flat circle indices (m,) in ``gs_compact``'s order, and the
        status with the circles' mask bits and ``BAD_INPUT``."""
        n_v = self.data.base.dims[1]
        (i0, i1, fa), (k0, k1, fv) = (tuple(a[sl] for a in q.tilt_cell),
                                      tuple(a[sl] for a in q.speed_cell))
        one = F32(1)
        wa0, wv0 = one - fa, one - fv
        weights = (wa0 * wv0, wa0 * fv, fa * wv0, fa * fv)
        circles = (i0 * n_v + k0, i0 * n_v + k1, i1 * n_v + k0, i1 * n_v + k1)
        status = q.status[sl].copy()
        mk = np.zeros(status.shape, dtype=np.uint8)
        for w, c in zip(weights, circles, strict=True):
            mk |= np.where(w != 0, self._mask[c], 0).astype(np.uint8)
        status |= np.where(mk != 0, INFEASIBLE, 0).astype(np.uint8)
        status |= np.where(mk & MASK_NO_GAINS, NO_GAINS, 0).astype(np.uint8)
        status = np.where(q.bad[sl], BAD_INPUT, status).astype(np.uint8)
        return weights, circles, status

    def _evaluate(self, q, sl):
        """Outputs (m, n_value) float32 and status (m,) of the queries ``sl`` of ``q``."""
        weights, circles, status = self._cell(q, sl)
        live = (status & UNUSABLE) == 0
        # the harmonics of the azimuth: one sin/cos pair, then angle addition
        s1, c1 = sincos_f32(q.xi[sl])
        basis = [np.ones_like(s1), c1, s1]
        ck, sk = c1, s1
        for _ in range(2, (self._top - 1) // 2 + 1):
            ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
            basis += [ck, sk]
        acc = np.zeros((s1.size, self.data.n_value), dtype=np.float32)
        for w, c in zip(weights, circles, strict=True):
            use = live & (w != 0)
            rows = self._rows[c]  # (m, n_value)
            for j, b in enumerate(basis):
                on = use[:, None] & (j < rows)
                if not np.any(on):
                    break
                g = w * b  # the series' weight: corner weight times the harmonic
                acc = np.where(on, acc + g[:, None] * self._coef[c, j], acc)
        return acc, status
