"""The dense runtime data: a table as the C runtime holds it (float32, infeasible gains
as zeros, the mask), with the firmware record's vehicle constants, S2 state map and
controller parameters, and its CRC-32 as ``gs_table_crc32`` computes it.

:func:`runtime_data` converts a loaded table and nothing else (docs/table-format.md,
"The firmware record"); the lookups over it are :mod:`gainsched.firmware.runtime`, which
re-exports these names.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

from ..constants import MASK_NO_GAINS, MAX_XI
from ..errors import InputError
from ..schedule.arrays import GainSchedule
from ..schedule.closedform import polynomial_drag
from ..schedule.onboard import VEHICLE_FIELDS

__all__ = [
    "N_BASE_STATES",
    "MAX_OFFSET_HARMONICS",
    "DESCRIPTOR_CHUNKS",
    "VEHICLE_FIELDS",
    "VehicleConstants",
    "vehicle_fields",
    "RuntimeData",
    "runtime_data",
    "crc32_of",
    "c_identifier",
]

F32 = np.float32
N_BASE_STATES = 11  # never permuted by the mirror (GS_N_BASE_STATES)
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


#: the chunks of :meth:`RuntimeData.crc_chunks` that describe the table (sizes, scale)
#: rather than hold its data arrays
DESCRIPTOR_CHUNKS = ("dims", "xi_scale", "n_xi_tilt0", "offset_harmonics", "reverse")
#: the chunks a reverse half shares with its table in a header (the same axes and state
#: map, bit for bit): stored once
SHARED_CHUNKS = ("xi", "speed", "xi_dot", "tilt", "state_sign", "state_perm")


@dataclass(frozen=True)
class RuntimeData(GainSchedule):
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
    ``reverse``: the same of the vehicle's mirror image, whose data serve the reversed
    circles (:attr:`Table.reverse <gainsched.schedule.tables.Table>`); None when the
    vehicle is its own mirror image. Its CRC-32 is the last chunk of this one's (as
    ``gs_table_crc32`` reads ``gs_table.reverse``), and :meth:`nbytes` counts its data.
    """

    name: str
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
    reverse: RuntimeData | None = None

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
        if self.reverse is not None:  # the reverse half's CRC-32 (gs_table.reverse)
            yield "reverse", np.array([self.reverse.crc32()], dtype="<u4").tobytes()

    def crc32(self) -> int:
        """CRC-32 (zlib, IEEE) of :meth:`crc_chunks`, as ``gs_table_crc32`` computes it."""
        return crc32_of(self.crc_chunks())

    def nbytes(self) -> int:
        """Bytes of table data the firmware stores (all arrays, without padding): with a
        reverse half, its arrays too, but for the axes and state map it shares."""
        own = sum(len(b) for k, b in self.crc_chunks() if k not in DESCRIPTOR_CHUNKS)
        if self.reverse is None:
            return own
        return own + sum(len(b) for k, b in self.reverse.crc_chunks()
                         if k not in DESCRIPTOR_CHUNKS + SHARED_CHUNKS)


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
    if getattr(table, "loop_margins", None) is not None:  # the header's comment
        from ..schedule.viewer import margin_lines

        meta["margins"] = "\n".join(margin_lines(table, maps=False))
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
        reverse=None if getattr(table, "reverse", None) is None else runtime_data(table.reverse),
        **axes,
    )
