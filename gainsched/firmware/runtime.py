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
table data (the numbers the firmware holds).
"""

from __future__ import annotations

import zlib
from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np

from .. import constants
from ..constants import MASK_NO_GAINS, MAX_XI
from ..errors import InputError
from ..schedule.closedform import polynomial_drag
from ..schedule.onboard import VEHICLE_FIELDS

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
N_BASE_STATES = 11  # never permuted by the mirror (GS_N_BASE_STATES)
SNAP = F32(2.0**-12)  # cell fractions this close to 0 or 1 are put on the grid plane
MAX_OFFSET_HARMONICS = 8  # GS_MAX_OFFSET_HARMONICS


@dataclass(frozen=True)
class VehicleConstants:
    """What the compiled closed form knows of the vehicle (paper eqs. 15-18).

    Attribute names follow :class:`gainsched.model.reduced.Model`, so that
    :func:`gainsched.schedule.closedform.closed_form` takes it as its model.

    Attributes
    ----------
    m : float, kg
    g : float, m/s^2
    r : float, m
        COG radius ``rho + L_e``.
    min_tension : float, N
        The config's taut margin: below it the feed-forward sets ``LOW_TENSION``.
    mu1, mu2 : float, N s/m and N s^2/m^2
        Body drag ``(mu1 + mu2 |v|) v`` of the config's pure-drag effects, summed.
    J : ndarray, shape (3, 3), kg m^2
    alloc_inv : ndarray, shape (4, 4)
        ``(T_C N, tau_B N m) -> motor thrusts N``.
    """

    m: float
    g: float
    r: float
    min_tension: float
    mu1: float
    mu2: float
    J: np.ndarray
    alloc_inv: np.ndarray

    @classmethod
    def from_array(cls, a) -> VehicleConstants:
        """From the ``gs_vehicle`` float32 layout (:data:`VEHICLE_FIELDS`), in float64."""
        f = vehicle_fields(np.asarray(a, dtype=np.float64))
        scalar = {k: float(x[0]) for k, x in f.items() if x.size == 1}
        return cls(scalar["mass"], scalar["g"], scalar["radius"], scalar["min_tension"],
                   scalar["drag_mu1"], scalar["drag_mu2"], f["J"].reshape(3, 3),
                   f["alloc_inv"].reshape(4, 4))

    def closed_form_drag(self):
        """The closed form's tangential drag ``D(v) -> (D, D', D'')`` of ``mu1, mu2``."""
        return polynomial_drag(self.mu1, self.mu2)


def vehicle_fields(a) -> dict[str, np.ndarray]:
    """A ``gs_vehicle`` array (:data:`VEHICLE_FIELDS` order) split into its fields."""
    ends = np.cumsum(list(VEHICLE_FIELDS.values()))
    return dict(zip(VEHICLE_FIELDS, np.split(np.asarray(a), ends[:-1]), strict=True))


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


#: the chunks of :meth:`RuntimeData.crc_chunks` that describe the table (sizes, scale)
#: rather than hold its data arrays
DESCRIPTOR_CHUNKS = ("dims", "xi_scale", "n_xi_tilt0", "offset_harmonics")


@dataclass(frozen=True)
class RuntimeData:
    """A table as the runtime holds it: float32 data, infeasible gains as zeros, the mask.

    Arrays (shapes as in :class:`gainsched.schedule.tables.Table`): ``xi, speed, xi_dot, tilt,
    K_tilt0, K, u_d, phi_d, state_sign`` float32; ``state_perm, mask`` uint8 with
    ``mask = reasons | MASK_NO_GAINS`` where a point has no finite gains or nominal.
    ``P_x[state_perm[j], j] = state_sign[j]`` is the S2 map of the LQR state.
    ``vehicle``: the closed-form constants of the feed-forward (:data:`VEHICLE_FIELDS`),
    float32 (31,), from the table's firmware record (None: no feed-forward).
    ``controller``: the controller's design parameters of the firmware record
    (:data:`gainsched.schedule.onboard.CONTROLLER_KEYS`), None when not known.
    ``offsets``: the nominal's pitch and yaw offsets per circle, float32 (n_a, n_v, 2,
    2 H + 1), Fourier coefficients in the azimuth; None when the table has none.
    """

    name: str
    xi: np.ndarray
    speed: np.ndarray
    xi_dot: np.ndarray
    tilt: np.ndarray
    K_tilt0: np.ndarray
    K: np.ndarray
    u_d: np.ndarray
    phi_d: np.ndarray
    state_sign: np.ndarray
    state_perm: np.ndarray
    mask: np.ndarray
    xi_scale: np.float32
    state_names: tuple = ()
    config_sha256: str = ""
    meta: dict = field(default_factory=dict)
    vehicle: np.ndarray | None = None
    offsets: np.ndarray | None = None
    controller: dict | None = None

    @property
    def dims(self) -> tuple[int, int, int, int]:
        """``(n_tilt, n_speed, n_xi, n_state)``."""
        return self.tilt.size, self.xi_dot.size, self.xi.size, self.state_sign.size

    @property
    def n_xi_tilt0(self) -> int:
        """Azimuths of the tilt-0 gains: 1 (independent of xi) or ``n_xi``."""
        return 1 if self.K_tilt0.ndim == 3 else self.xi.size

    def crc_chunks(self):
        """``(label, bytes)`` in CRC order: dims (uint32 LE), xi_scale, the tilt-0 azimuth
        count when it is not 1 (so that tables without it keep their CRC), then the
        arrays."""
        dims = np.array(self.dims, dtype="<u4")
        yield "dims", dims.tobytes()
        yield "xi_scale", np.array([self.xi_scale], dtype="<f4").tobytes()
        if self.n_xi_tilt0 != 1:
            yield "n_xi_tilt0", np.array([self.n_xi_tilt0], dtype="<u4").tobytes()
        for key in ("xi", "speed", "xi_dot", "tilt", "K_tilt0", "K", "u_d", "phi_d", "state_sign"):
            yield key, np.ascontiguousarray(getattr(self, key), dtype="<f4").tobytes()
        for key in ("state_perm", "mask"):
            yield key, np.ascontiguousarray(getattr(self, key), dtype=np.uint8).tobytes()
        if self.vehicle is not None:
            yield "vehicle", np.ascontiguousarray(self.vehicle, dtype="<f4").tobytes()
        if self.offsets is not None:
            H = (self.offsets.shape[-1] - 1) // 2
            yield "offset_harmonics", np.array([H], dtype="<u4").tobytes()
            yield "offsets", np.ascontiguousarray(self.offsets, dtype="<f4").tobytes()

    def crc32(self) -> int:
        """CRC-32 (zlib, IEEE) of :meth:`crc_chunks`, as ``gs_table_crc32`` computes it."""
        return crc32_of(self.crc_chunks())

    def nbytes(self) -> int:
        """Bytes of table data the firmware stores (all arrays, without padding)."""
        return sum(len(b) for k, b in self.crc_chunks() if k not in DESCRIPTOR_CHUNKS)


def crc32_of(chunks) -> int:
    """CRC-32 (zlib, IEEE) of ``(label, bytes)`` chunks in order: a table's
    ``crc_chunks()``, as ``gs_table_crc32`` reads it."""
    crc = 0
    for _, chunk in chunks:
        crc = zlib.crc32(chunk, crc)
    return crc & 0xFFFFFFFF


def c_identifier(name: str) -> str:
    """A lower-case C identifier prefix from a table name (``paper-v2`` -> ``paper_v2``)."""
    out = "".join(ch if ch.isalnum() and ch.isascii() else "_" for ch in str(name).lower())
    out = out.strip("_") or "table"
    return out if not out[0].isdigit() else f"t{out}"


def _signed_permutation(P, source="") -> tuple[np.ndarray, np.ndarray]:
    """``(perm, sign)`` with ``P[perm[j], j] = sign[j]``; P must be a signed involution."""
    n = P.shape[0]
    perm = np.abs(P).argmax(0)
    sign = P[perm, np.arange(n)]
    Q = np.zeros_like(P)
    Q[perm, np.arange(n)] = sign
    ok = (
        np.array_equal(Q, P)
        and np.all(np.abs(sign) == 1)
        and np.array_equal(perm[perm], np.arange(n))
        and np.array_equal(sign[perm], sign)
        and n >= N_BASE_STATES
        and np.array_equal(perm[:N_BASE_STATES], np.arange(N_BASE_STATES))
    )
    if not ok or n > 255:
        raise InputError(source, "state map", "S2 state map is not a signed involutive permutation")
    return perm.astype(np.uint8), sign.astype(np.float32)


def _offsets(table, src):
    """The table's attitude offsets in float32, or None when it has none."""
    off = getattr(table, "offsets", None)
    if off is None or not np.any(off):
        return None
    H = (off.shape[-1] - 1) // 2
    if H > MAX_OFFSET_HARMONICS:
        raise InputError(src, "nominal/attitude_offsets",
                         f"at most {MAX_OFFSET_HARMONICS} harmonics, got {H}")
    return np.ascontiguousarray(off, dtype=np.float32)


def runtime_data(table) -> RuntimeData:
    """Convert a loaded :class:`~gainsched.schedule.tables.Table` into the runtime's float32 form.

    Raises InputError if the table cannot be represented (float32 axes collapse,
    too many azimuths, state map not a signed permutation).
    """
    src = table.source or "<table>"
    n_a, n_v, n_xi = table.reasons.shape
    if n_xi > MAX_XI:
        raise InputError(src, "axes/xi", f"at most {MAX_XI} azimuth samples, got {n_xi}")
    axes = {}
    for key in ("xi", "speed", "xi_dot", "tilt"):
        a = np.asarray(getattr(table, key), dtype=np.float32)
        if a.size > 1 and np.any(np.diff(a) <= 0):
            raise InputError(src, f"axes/{key}", "not strictly increasing in float32")
        axes[key] = a
    if not axes["xi_dot"][0] > 0:
        raise InputError(src, "axes/xi_dot", "must be positive")
    if np.any(table.reasons & MASK_NO_GAINS):
        raise InputError(src, "feasibility/reasons", f"bit {MASK_NO_GAINS:#x} is reserved")
    record = getattr(table, "firmware", None)
    if record is None:
        raise InputError(src, "firmware", "missing: the table carries no firmware record "
                         "(docs/table-format.md); rebuild it (gainsched build CONFIG)")
    perm, sign = _signed_permutation(np.asarray(record.state_map), src)
    K0 = np.asarray(table.K_tilt0, dtype=np.float64)
    K = np.asarray(table.K, dtype=np.float64)
    u_d = np.asarray(table.u_d, dtype=np.float64)
    phi_d = np.asarray(table.phi_d, dtype=np.float64)
    big = np.finfo(np.float32).max
    fin0 = np.all(np.isfinite(K0) & (np.abs(K0) <= big), axis=(-2, -1))  # (n_v[, n_xi])
    finK = np.all(np.isfinite(K) & (np.abs(K) <= big), axis=(-2, -1))  # (n_a-1, n_v, n_xi)
    good = np.empty((n_a, n_v, n_xi), dtype=bool)
    good[0] = fin0 if K0.ndim == 4 else fin0[:, None]
    good[1:] = finK
    good &= np.all(np.isfinite(u_d) & (np.abs(u_d) <= big), axis=-1)
    good &= np.isfinite(phi_d) & (np.abs(phi_d) <= big)
    lost = ~good & (table.reasons == 0)
    if np.any(lost):  # load_table checked finiteness at feasible points: a float32 overflow
        i, j, k = (int(x) for x in np.argwhere(lost)[0])
        fits = lambda x: bool(np.all(np.abs(x) <= big))  # noqa: E731
        k0 = (j, k) if K0.ndim == 4 else (j,)
        key, idx = ((("gains/K_tilt0", k0) if i == 0 else ("gains/K", (i - 1, j, k)))
                    if not fits(K0[k0] if i == 0 else K[i - 1, j, k]) else
                    ("nominal/u_d", (i, j, k)) if not fits(u_d[i, j, k]) else
                    ("nominal/phi_d", (i, j, k)))
        raise InputError(src, f"{key}[{', '.join(map(str, idx))}]",
                         "overflows float32 at a feasible point; the firmware cannot hold it")
    mask = np.asarray(table.reasons, dtype=np.uint8) | np.where(good, 0, MASK_NO_GAINS).astype(
        np.uint8
    )

    def clean(x):
        x = np.where(np.isfinite(x) & (np.abs(x) <= big), x, 0.0)
        return np.ascontiguousarray(x, dtype=np.float32)

    names = tuple(str(table.attrs.get("state_names", "")).split(",")) if table.attrs else ()
    meta = {
        k: table.attrs[k]
        for k in ("tool_version", "schema", "terminal", "rate_hz", "radius_m", "config_name",
                  "control_law")
        if k in table.attrs
    }
    return RuntimeData(
        name=c_identifier(table.name if "config_name" in table.attrs else "table"),
        xi_scale=F32(n_xi / (2 * np.pi)),
        state_sign=sign,
        state_perm=perm,
        mask=np.ascontiguousarray(mask),
        K_tilt0=clean(K0),
        K=clean(K),
        u_d=clean(u_d),
        phi_d=clean(phi_d),
        state_names=names,
        config_sha256=str(table.config_sha256),
        meta=meta,
        vehicle=np.asarray(record.vehicle, dtype=np.float64).astype(np.float32),
        offsets=_offsets(table, src),
        controller=dict(record.controller),
        **axes,
    )


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
        Kg = np.empty((n_a, n_v, n_xi, 4 * n))
        Kg[0] = d.K_tilt0.reshape(n_v, d.n_xi_tilt0, 4 * n)  # broadcast when 1
        if n_a > 1:
            Kg[1:] = d.K.reshape(n_a - 1, n_v, n_xi, 4 * n)
        self._K = Kg.reshape(-1, 4 * n)
        self._U = d.u_d.astype(np.float64).reshape(-1, 4)
        self._P = d.phi_d.astype(np.float64).reshape(-1)
        self._mask = d.mask.reshape(-1)
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
        return attitude_offsets(self.data, xi, alpha, circ, wc, mirrored, status)

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
        pts = [0] * 8
        w = [0.0] * 8
        m = 0
        for c in range(8):
            bt, bv, bx = (c >> 2) & 1, (c >> 1) & 1, c & 1
            p = (ia[bt] * n_v + iv[bv]) * n_xi + ix[bx]
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
