"""Gain tables on disk (HDF5): layout in ``docs/table-format.md``.

Tables are written into an in-memory HDF5 image (no timestamps, fixed
creation order) and then atomically renamed into place, so the same config
gives byte-identical files and an interrupted build leaves the old file intact.

Integrity: every dataset carries the SHA-256 of its dtype, shape and bytes
(attribute ``sha256``) and the root carries ``data_sha256`` over those and the
root attributes, so :func:`load_table` (and with it ``inspect``, ``check``,
``export-c``, ``simulate``) refuses a file whose data changed after the build,
naming the dataset. Gains, nominal thrusts and roll must be finite at every
feasible point.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from .. import __version__
from ..config import N_STATE
from ..constants import CONTROL_LAW, REASONS
from ..errors import InputError
from ..model.reduced import Model
from ..model.symmetry import mirror_effects
from ..publish import write_atomic
from .arrays import GainSchedule
from .grid import mirror_config
from .h5io import create_dataset, create_group, dataset_sha256, datasets, root_sha256
from .linearize import INPUT_NAMES, lqr_state_names
from .margins import LoopMargins
from .onboard import FirmwareRecord, record_from_config, record_from_datasets
from .tablechecks import check_feasible_finite, check_meaning

__all__ = ["SCHEMA", "Table", "table_bytes", "write_table", "load_table", "table_from_bytes",
           "config_from_table"]

SCHEMA = "gainsched-table/2"
#: the format before the firmware record (``firmware/``): refused, with a line to rebuild
PREVIOUS_SCHEMA = "gainsched-table/1"


@dataclass(frozen=True)
class Table(GainSchedule):
    """A gain schedule as loaded from its HDF5 file: axes, gains, nominal, feasibility.

    Made by :func:`load_table` (checked; docs/table-format.md describes the file). It
    holds the fundamental domain only, tilt >= 0 and xi_dot > 0: negative tilts and
    reversed circles follow from the symmetries, which
    :class:`gainsched.Interpolator` applies. Sizes: ``n_a`` tilts, ``n_v`` speeds,
    ``n_xi`` azimuths, ``n`` LQR states (11 for configs/paper.toml, in the order of
    ``attrs["state_names"]``), 4 inputs (motor thrusts T1..T4, N). Gains are for
    ``u = u_d - K (x - x_d)``, in N per state unit; the arrays are float64 as stored.

    Attributes
    ----------
    xi : ndarray, shape (n_xi,)
        Azimuth axis, rad, uniform on [0, 2 pi).
    speed : ndarray, shape (n_v,)
        Tangential COG speed axis, m/s, strictly increasing and > 0.
    xi_dot : ndarray, shape (n_v,)
        Azimuth rate axis ``speed / r`` (``r = rho + L_e``, ``attrs["radius_m"]``), rad/s:
        the lookup's speed coordinate.
    tilt : ndarray, shape (n_a,)
        Circle tilt axis ``alpha_C``, rad, strictly increasing, ``tilt[0] == 0``.
    K_tilt0 : ndarray, shape (n_v, 4, n) or (n_v, n_xi, 4, n)
        Gains at tilt 0, N per state unit: independent of xi, or per azimuth when an
        effect changes with the azimuth of a level circle (:attr:`per_azimuth_tilt0`).
        NaN where infeasible.
    K : ndarray, shape (n_a - 1, n_v, n_xi, 4, n)
        Gains at ``tilt[1:]``, N per state unit; NaN where infeasible. :meth:`K_full`
        gives the gains of every tilt on one grid.
    u_d : ndarray, shape (n_a, n_v, n_xi, 4)
        Nominal motor thrusts T1..T4, N.
    phi_d : ndarray, shape (n_a, n_v, n_xi)
        Nominal roll, rad.
    tension : ndarray, shape (n_a, n_v, n_xi)
        Nominal tether tension, N.
    reasons : ndarray of uint8, shape (n_a, n_v, n_xi)
        Feasibility bits, 0 = feasible (1 slack, 2 thrust below minimum, 4 thrust above
        maximum, 8 trim failed, 16 infeasible elsewhere on the circle;
        :class:`gainsched.constants.Reason`).
    spectral_radius : ndarray, shape (n_a, n_v)
        Closed-loop monodromy spectral radius per circle (< 1: stable); NaN if
        infeasible.
    Q : ndarray, shape (n, n)
        LQR state weight (the config's Q, zero for effect states).
    R : ndarray, shape (4, 4)
        LQR input weight.
    dt : ndarray, shape (n_v,)
        Discretisation step per speed, period / steps, s.
    config_text : str
        The config TOML text the table was built from (:func:`gainsched.config_from_text`
        reads it back).
    config_sha256 : str
        SHA-256 (hex) of ``config_text``.
    attrs : dict
        The file's root attributes: ``schema``, ``tool_version``, ``config_name``,
        ``config_sha256``, ``terminal``, ``rate_hz`` (Hz), ``radius_m`` (m),
        ``state_names`` and ``input_names`` (comma-separated, K's column and row order),
        ``control_law``, ``data_sha256``.
    source : str
        The file it was read from (errors name it); ``""`` when not read from a file.
    offsets : ndarray, shape (n_a, n_v, 2, 2 H + 1), or None
        Fourier coefficients in the azimuth (rad, ``[c0, a_1..a_H, b_1..b_H]``) of the
        nominal's pitch and yaw offsets per circle
        (:class:`~gainsched.schedule.offsets.AttitudeOffsets`); None: all zero (a table
        of a config with ``attitude_offsets = "zero"``, or older).
    mode_tau, mode_frequency, mode_damping : ndarray, shape (n_a, n_v, M), or None
        The M slowest closed-loop Floquet modes per circle, slowest first: time constant
        ``-T / ln|lambda|`` s, frequency rad/s, damping ratio
        (:mod:`gainsched.schedule.modes`); NaN if infeasible; None in a table built
        before they were stored.
    mode_shape : ndarray, shape (n_a, n_v, M, n), or None
        Their eigenvector magnitudes in the states' units, largest entry 1
        (:func:`~gainsched.schedule.modes.dominant_states` names the states).
    grid_auto : dict or None
        How the build chose the speed and tilt axes (``grid_auto`` in the file, JSON;
        :meth:`gainsched.schedule.refine.GridChoice.record`): the bound (a fraction), the
        ranges as written, the errors met at the cell midpoints (fractions: ``gain_error``,
        ``thrust_error``, ``roll_error``), the worst midpoint loop ``worst_rho`` and the
        cost in circles; None: the axes were given as lists.
    firmware : FirmwareRecord or None
        What the firmware needs beyond the gains and the nominal, computed at the build
        (``firmware/`` in the file; :class:`~gainsched.schedule.onboard.FirmwareRecord`):
        the feed-forward's vehicle constants, the S2 state map, the controller's design
        parameters. Every loaded table has it; None only in a Table made by hand.
    loop_margins : LoopMargins or None
        The stability margins of every circle's loop, arrays (n_a, n_v) (``(n_a, n_v, 4)``
        per motor; :meth:`margins`); None in a table built with ``[control] margins =
        false``.
    reverse : Table or None
        For a vehicle that is not its own mirror image (a centre of mass off its plane of
        symmetry, unequal motors; docs/symmetry.md): the same table of its mirror image
        (``reverse/`` in the file), whose forward circles are the vehicle's reversed ones
        mirrored; its axes, weights, config and attributes are this table's. None when
        the vehicle is its own mirror image.
    name : str
        Property: the config's name (``attrs["config_name"]``).
    per_azimuth_tilt0 : bool
        Property: whether ``K_tilt0`` is stored per azimuth, shape (n_v, n_xi, 4, n).
    state_names, input_names : tuple of str
        Properties: the LQR states (K's columns, length n) and the inputs (K's rows:
        ``T1..T4``), from ``attrs``.

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> table.K_full().shape                  # (tilt, speed, azimuth, input, state)
    (7, 19, 36, 4, 11)
    >>> table.state_names
    ('delta', 'xi', 'delta_dot', 'xi_dot', 'phi', 'theta', 'chi', 'omega_x', 'omega_y',
     'omega_z', 'int_delta')
    >>> float(table.attrs["radius_m"]), round(float(table.xi_dot[-1]), 4)  # m, rad/s
    (1.6, 9.375)
    >>> repr(table)[:59], len(repr(table)) < 200  # one line: no arrays printed
    ("Table('paper', 7 tilts 0-40 deg x 19 speeds 1.3-15 m/s x 36", True)
    """

    tension: np.ndarray
    reasons: np.ndarray
    spectral_radius: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    dt: np.ndarray
    config_text: str
    config_sha256: str
    attrs: dict
    source: str = ""
    offsets: np.ndarray | None = None
    mode_tau: np.ndarray | None = None
    mode_frequency: np.ndarray | None = None
    mode_damping: np.ndarray | None = None
    mode_shape: np.ndarray | None = None
    grid_auto: dict | None = None
    firmware: FirmwareRecord | None = None
    reverse: Table | None = None
    loop_margins: LoopMargins | None = None

    @property
    def name(self) -> str:
        return str(self.attrs["config_name"])

    def __repr__(self) -> str:
        """One line (the arrays are megabytes: a notebook cell would print them all)."""
        tilts = np.rad2deg(self.tilt)
        feasible = np.count_nonzero(self.reasons == 0) / max(self.reasons.size, 1)
        return (f"Table({self.name!r}, {tilts.size} tilts {tilts.min():g}-{tilts.max():g} deg x "
                f"{self.speed.size} speeds {self.speed.min():g}-{self.speed.max():g} m/s x "
                f"{self.xi.size} azimuths, {len(self.state_names)} states, "
                f"{feasible:.1%} feasible, source={self.source!r})")

    def built_from(self, config) -> bool:
        """Whether the table was built from ``config``: the config it embeds, or, for a
        grid the build chose (``grid_auto``), the config with the ranges it was given
        (``source_config_sha256``; the embedded one holds the chosen breakpoints)."""
        return config.sha256 in (self.config_sha256,
                                 (self.grid_auto or {}).get("source_config_sha256"))

    @property
    def state_names(self) -> tuple[str, ...]:
        """The LQR states in K's column order (``attrs["state_names"]``)."""
        return tuple(str(self.attrs["state_names"]).split(","))

    @property
    def input_names(self) -> tuple[str, ...]:
        """The inputs in K's row order (``attrs["input_names"]``: T1..T4)."""
        return tuple(str(self.attrs["input_names"]).split(","))

    @property
    def per_azimuth_tilt0(self) -> bool:
        """Whether the tilt-0 gains are stored per azimuth (``K_tilt0`` (n_v, n_xi, 4, n))."""
        return self.K_tilt0.ndim == 4

    def margins(self, speed: float | None = None, tilt_deg: float | None = None) -> LoopMargins:
        """The stability margins of the table's loops (docs/margins.md): every circle's,
        arrays (n_a, n_v), or the grid circle's at ``speed`` (m/s) and ``tilt_deg``.

        Raises
        ------
        ValueError
            The table was built with ``[control] margins = false`` (or before margins
            were stored), or the speed or tilt is not on the grid.
        """
        if self.loop_margins is None:
            raise ValueError(f"{self.source or self.name}: no margins in this table (built "
                             "with [control] margins = false, or before they were stored)")
        if speed is None and tilt_deg is None:
            return self.loop_margins
        if speed is None or tilt_deg is None:
            raise ValueError("give both speed and tilt_deg (one circle), or neither")
        i = _axis_index(np.rad2deg(self.tilt), tilt_deg, "tilt_deg")
        j = _axis_index(self.speed, speed, "speed")
        return self.loop_margins.at(i, j)

    def K_full(self) -> np.ndarray:
        """Gains on the regular grid (n_a, n_v, n_xi, 4, n), a tilt-0 slice independent of
        xi broadcast over it."""
        k0 = self.K_tilt0 if self.per_azimuth_tilt0 else self.K_tilt0[:, None]
        k0 = np.broadcast_to(k0, (1, *self.K.shape[1:]))
        return np.concatenate([k0, self.K], axis=0)


def _axis_index(axis, value, name):
    """The index of ``value`` on a grid axis (to 1e-9), or ValueError listing the axis."""
    hit = np.flatnonzero(np.isclose(axis, value, rtol=0, atol=1e-9))
    if len(hit) != 1:
        raise ValueError(f"{name} = {value} is not on the grid: {np.round(axis, 6).tolist()}")
    return int(hit[0])


def table_bytes(config, grid, model=None, grid_auto: dict | None = None) -> bytes:
    """Serialise a built grid (``grid.GridResult``) to HDF5 bytes, deterministically, with
    the firmware record of ``config`` (:func:`~gainsched.schedule.onboard.record_from_config`);
    ``model``: the config's (:class:`gainsched.model.reduced.Model`, default built here);
    ``grid_auto``: the record of axes the build chose
    (:meth:`~gainsched.schedule.refine.GridChoice.record`), stored as sorted-key JSON."""
    if model is None:
        model = Model(config)
    speeds, tilts = config.grid.speeds, config.grid.tilts
    n_xi = config.grid.azimuth_samples
    n = grid.K.shape[-1]
    Qx = np.zeros((n, n))
    n_lqr = config.control.n_lqr
    Qx[:n_lqr, :n_lqr] = config.control.Q
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fapl_core(backing_store=False)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_V18, h5py.h5f.LIBVER_V18)
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    fcpl.set_obj_track_times(False)  # the root group would otherwise carry its creation time
    fid = h5py.h5f.create(b"gainsched-table", h5py.h5f.ACC_TRUNC, fapl=fapl, fcpl=fcpl)
    with h5py.File(fid) as f:
        a = f.attrs
        a["schema"] = SCHEMA
        a["tool_version"] = __version__
        a["config_name"] = config.name
        a["config_sha256"] = config.sha256
        a["terminal"] = config.control.terminal
        a["rate_hz"] = config.control.rate_hz
        a["radius_m"] = config.radius
        a["state_names"] = ",".join(lqr_state_names(model))
        a["input_names"] = ",".join(INPUT_NAMES)
        a["control_law"] = CONTROL_LAW
        create_dataset(f, "config_text", config.text)
        if grid_auto is not None:
            create_dataset(f, "grid_auto", json.dumps(grid_auto, sort_keys=True), None,
                    "how the build chose the speed and tilt axes (docs/grid.md), JSON")
        ax = create_group(f, "axes")
        create_dataset(ax, "xi", 2 * np.pi * np.arange(n_xi) / n_xi, "rad",
                       "azimuth, uniform, periodic")
        create_dataset(ax, "speed", speeds, "m/s", "tangential COG speed")
        create_dataset(ax, "xi_dot", speeds / config.radius, "rad/s",
                       "azimuth rate = speed / (rho + L_e)")
        create_dataset(ax, "tilt", tilts, "rad", "circle tilt alpha_C; tilt[0] = 0")
        _write_solution(f, grid)
        w = create_group(f, "weights")
        create_dataset(w, "Q", Qx)
        create_dataset(w, "R", np.asarray(config.control.R))
        _write_firmware(create_group(f, "firmware"), record_from_config(config))
        if grid.reverse is not None:
            _write_reverse(create_group(f, "reverse"), config, model, grid.reverse)
        digests = {}
        for name, ds in datasets(f).items():
            digests[name] = ds.attrs["sha256"] = dataset_sha256(ds[()])
        a["data_sha256"] = root_sha256(dict(a), digests)
        f.flush()
        return f.id.get_file_image()


def _write_solution(parent, grid) -> None:
    """The solved grid's groups under ``parent`` (the file's root, or ``reverse/`` for
    the mirror image's): gains, nominal, feasibility and closed loop
    (docs/table-format.md)."""
    g = create_group(parent, "gains")
    if grid.level_invariant:
        K0, S0, doc = grid.K[0, :, 0], grid.S[0, :, 0], "xi-independent), (speed, 4, n)"
    else:  # an effect changes with the azimuth of a level circle
        K0, S0, doc = grid.K[0], grid.S[0], "per azimuth), (speed, xi, 4, n)"
    create_dataset(g, "K_tilt0", K0, "SI", f"gains at tilt 0 ({doc}")
    create_dataset(g, "K", grid.K[1:], "SI", "gains at tilt[1:], (tilt-1, speed, xi, 4, n)")
    create_dataset(g, "S_tilt0", S0, "SI", "Riccati cost-to-go at tilt 0")
    create_dataset(g, "S", grid.S[1:], "SI", "Riccati cost-to-go at tilt[1:]")
    nm = create_group(parent, "nominal")
    create_dataset(nm, "u_d", grid.u_d, "N", "nominal motor thrusts (tilt, speed, xi, 4)")
    create_dataset(nm, "phi_d", grid.phi_d, "rad", "nominal roll")
    create_dataset(nm, "tension", grid.tension, "N", "nominal tether tension")
    if np.any(grid.offsets):
        create_dataset(nm, "attitude_offsets", grid.offsets, "rad",
                "pitch and yaw offsets per circle: Fourier coefficients in the azimuth "
                "(tilt, speed, [theta, chi], [1, cos k xi, sin k xi])")
    fe = create_group(parent, "feasibility")
    ds = create_dataset(fe, "reasons", grid.reasons, None, "bit mask, 0 = feasible")
    for bit, text in REASONS.items():
        ds.attrs[f"bit_{bit}"] = text
    cl = create_group(parent, "closed_loop")
    create_dataset(cl, "spectral_radius", grid.spectral_radius, "-",
            "monodromy spectral radius per circle")
    create_dataset(cl, "periods", grid.sweeps, "-", "periods in the periodic terminal cost")
    create_dataset(cl, "steps", grid.steps, "-", "control steps per period")
    create_dataset(cl, "linearization_samples", grid.lin_samples, "-",
            "azimuths of exact linearisation per circle (1: time-invariant, tilt 0)")
    create_dataset(cl, "linearization_error", grid.lin_error, "-",
            "relative error check of the interpolated linearisation per circle")
    create_dataset(cl, "dt", grid.dt, "s", "discretisation step, period / steps")
    create_dataset(cl, "mode_tau", grid.mode_tau, "s",
            "time constants -T/ln|lambda| of the slowest closed-loop Floquet modes, "
            "slowest first (tilt, speed, mode)")
    create_dataset(cl, "mode_frequency", grid.mode_frequency, "rad/s",
            "their frequencies |arg lambda|/T (periodic loops: principal value)")
    create_dataset(cl, "mode_damping", grid.mode_damping, "-", "their damping ratios")
    create_dataset(cl, "mode_shape", grid.mode_shape, "-",
            "their eigenvector magnitudes in the states' units, largest entry 1 "
            "(tilt, speed, mode, state)")
    if not np.all(np.isnan(grid.gain_margin)):  # [control] margins (docs/margins.md)
        create_dataset(cl, "gain_margin", grid.gain_margin, "-", "factors on all motors' commands "
                "where a multiplier reaches the unit circle, (tilt, speed, [down, up])")
        create_dataset(cl, "input_gain_margin", grid.input_margin, "-",
                "the same for each motor alone, (tilt, speed, motor, [down, up])")
        create_dataset(cl, "delay_margin", grid.delay_margin, "s", "extra delay on the commands "
                "where a multiplier reaches the unit circle (tilt, speed)")
        create_dataset(cl, "crossover", grid.crossover, "rad/s", "the frequency of that "
                "multiplier, the loop's crossover (NaN: none known), (tilt, speed)")


def _write_reverse(r, config, model, grid) -> None:
    """The mirror image's grid under ``reverse/``: a vehicle that is not its own mirror
    image has its reversed circles served from its image's forward ones
    (docs/symmetry.md, docs/table-format.md)."""
    image = mirror_config(config)
    create_dataset(r, "mirror_image", json.dumps(mirror_effects(model.effects),
                                          sort_keys=True), None,
            "the effect parameters of the vehicle's mirror image under S2 that differ from "
            "its own, {kind: {name: value}}, JSON")
    _write_solution(r, grid)
    _write_firmware(create_group(r, "firmware"), record_from_config(image))


def config_from_table(table, *, unknown_effect_ok: bool = False):
    """The config a table was built from: its embedded ``config_text``, loaded and
    validated as ``gainsched validate`` loads a config (the one place it is parsed again).

    Parameters
    ----------
    table : Table
        A loaded table; errors name ``<its source>:config_text`` and the key.
    unknown_effect_ok : bool
        Return None, rather than raise, when the config names an effect this process
        does not know (one registered in another process); any other fault raises.

    Returns
    -------
    Config or None
    """
    from ..config import config_from_text

    try:
        return config_from_text(table.config_text, f"{table.source}:config_text")
    except InputError as exc:
        if (unknown_effect_ok and exc.where.startswith("effects.")
                and exc.message.startswith("unknown effect")):
            return None
        raise


def _write_firmware(g, record: FirmwareRecord) -> None:
    """The firmware record's datasets (docs/table-format.md, "The firmware record")."""
    create_dataset(g, "vehicle", record.vehicle, "SI", "the feed-forward's gs_vehicle constants: "
            "mass, g, radius, min_tension, drag_mu1, drag_mu2, J (3x3), alloc_inv (4x4)")
    create_dataset(g, "state_map", record.state_map, "-",
            "S2 map of the LQR state P_x (signed permutation, n x n)")
    create_dataset(g, "controller", record.controller_json(), None,
            "the controller's design parameters (gs_ctrl_params less sensing), JSON")


def write_table(path, config, grid, model) -> int:
    """Write the HDF5 table atomically; returns the file size in bytes."""
    data = table_bytes(config, grid, model)
    write_atomic(path, data)
    return len(data)


_REQUIRED = {
    "axes/xi": 1, "axes/speed": 1, "axes/xi_dot": 1, "axes/tilt": 1,
    "gains/K_tilt0": (3, 4), "gains/K": 5, "nominal/u_d": 4, "nominal/phi_d": 3,
    "nominal/tension": 3, "feasibility/reasons": 3, "closed_loop/spectral_radius": 2,
    "closed_loop/dt": 1, "weights/Q": 2, "weights/R": 2, "config_text": 0,
    "firmware/vehicle": 1, "firmware/state_map": 2, "firmware/controller": 0,
}
#: the datasets of a solved grid: at the root, and again under :data:`_REVERSE` for the
#: mirror image of a vehicle that is not its own (docs/table-format.md)
_SOLUTION = {k: v for k, v in _REQUIRED.items()
             if k.split("/")[0] in ("gains", "nominal", "feasibility", "closed_loop", "firmware")}
_REVERSE = "reverse/"


#: root attributes every table carries (written by :func:`table_bytes`)
_ATTRS = ("schema", "tool_version", "config_name", "config_sha256", "terminal", "rate_hz",
          "radius_m", "state_names", "input_names", "data_sha256")


def load_table(path) -> Table:
    """Load a gain table file (HDF5, as gainsched build writes it) and check its integrity.

    Checks the schema and root attributes, the data checksums (a corrupt or edited file
    is refused, naming the dataset), the shapes against the axes, and that gains,
    nominal thrusts and roll are finite at every feasible point.

    Parameters
    ----------
    path : str or path-like
        The table file, ``NAME.h5`` (docs/table-format.md), e.g. ``"tables/paper.h5"``.

    Returns
    -------
    Table
        The table's axes, gains, nominal and feasibility, float64 as stored, with
        ``source`` the path.

    Raises
    ------
    InputError
        The file cannot be read or is not a gainsched table, a dataset or attribute is
        missing or has the wrong shape, a checksum does not match, or a value at a
        feasible point is not finite; the message names the file and the dataset.

    See Also
    --------
    gainsched.Interpolator : Look up gains in the table as the firmware does.
    gainsched.table_summary : The table at a glance.

    Examples
    --------
    >>> table = gs.load_table("tables/paper.h5")
    >>> table.name, table.K.shape             # gains at tilt[1:]: (tilt, speed, xi, 4, n)
    ('paper', (6, 19, 36, 4, 11))
    >>> table.speed[[0, -1]].tolist(), np.rad2deg(table.tilt).round(1).tolist()  # m/s, deg
    ([1.3, 15.0], [0.0, 10.0, 20.0, 28.0, 34.0, 37.0, 40.0])
    >>> int(np.isfinite(table.spectral_radius).sum()), table.spectral_radius.size  # circles
    (113, 133)
    >>> gs.load_table("configs/paper.toml")
    Traceback (most recent call last):
        ...
    gainsched.errors.InputError: configs/paper.toml: not a readable HDF5 table (...)
    """
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise InputError(path, "", f"not a readable HDF5 table ({exc})") from None
    with f:
        return _read_guarded(f, path)


def _read_guarded(f, path) -> Table:
    """:func:`_read`, with the errors HDF5 raises on a damaged file turned into InputError."""
    try:
        return _read(f, path)
    except InputError:
        raise
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, UnicodeError) as exc:
        msg = " ".join(str(exc).split())[:160]
        raise InputError(path, "", f"damaged HDF5 file ({type(exc).__name__}: {msg})") from None


def table_from_bytes(data: bytes, source="<table>") -> Table:
    """:func:`load_table` for an in-memory file image (e.g. from :func:`table_bytes`)."""
    try:
        f = h5py.File(io.BytesIO(data), "r")
    except (OSError, ValueError) as exc:
        raise InputError(source, "", f"not a readable HDF5 table ({exc})") from None
    with f:
        return _read_guarded(f, source)


def _verify(f, path) -> None:
    """Per-dataset and root checksums (see the module docstring)."""
    if "data_sha256" not in f.attrs:
        raise InputError(path, "data_sha256", "missing: the file carries no data checksum "
                         "(built by gainsched < 0.2, or not by gainsched): rebuild it")
    digests = {}
    try:
        for name, ds in datasets(f).items():
            want = ds.attrs.get("sha256")
            got = digests[name] = dataset_sha256(ds[()])
            if want is None:
                raise InputError(path, name, "missing its sha256 attribute")
            if (want.decode() if isinstance(want, bytes) else str(want)) != got:
                raise InputError(path, name, "checksum mismatch: the data changed after the "
                                 "build (corrupt or edited file); rebuild the table")
    except InputError:  # a ValueError too: keep the dataset it names
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(path, "", f"unreadable dataset ({exc})") from None
    if root_sha256(dict(f.attrs), digests) != _decoded(f.attrs["data_sha256"]):
        raise InputError(path, "data_sha256", "checksum mismatch: attributes or datasets were "
                         "added, removed or edited after the build; rebuild the table")


def _decoded(v):
    return v.decode() if isinstance(v, bytes) else v


def _read(f, path) -> Table:
    schema = _decoded(f.attrs.get("schema"))
    if schema == PREVIOUS_SCHEMA:
        raise InputError(path, "schema", f"{schema!r}: built before the firmware record "
                         f"({SCHEMA!r}, docs/table-format.md); rebuild the table "
                         "(gainsched build CONFIG)")
    if schema != SCHEMA:
        raise InputError(path, "schema", f"must be {SCHEMA!r}, got {schema!r}")
    for key in _ATTRS:
        if key not in f.attrs:
            raise InputError(path, key, "missing root attribute")
    d = _read_datasets(f, path, "", _REQUIRED)
    attrs = {k: _decoded(v) for k, v in f.attrs.items()}
    xi, speed, tilt = d["axes/xi"], d["axes/speed"], d["axes/tilt"]
    for key, arr in (("axes/xi", xi), ("axes/speed", speed), ("axes/tilt", tilt)):
        if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(np.diff(arr) <= 0):
            raise InputError(path, key, "must be finite and strictly increasing")
    if not np.allclose(xi, 2 * np.pi * np.arange(xi.size) / xi.size, rtol=0, atol=1e-12):
        raise InputError(path, "axes/xi", "must be uniform on [0, 2 pi)")
    if tilt[0] != 0:
        raise InputError(path, "axes/tilt", "must start at 0")
    if speed[0] <= 0:
        raise InputError(path, "axes/speed", "must be positive")
    n = d["gains/K_tilt0"].shape[-1]
    names = str(attrs["state_names"]).split(",")
    if n < N_STATE or len(names) != n:
        raise InputError(path, "gains/K_tilt0", f"{n} state columns; need >= {N_STATE} and one per "
                         f"name in state_names ({len(names)})")
    s = _solution(f, path, "", d, n)
    grid_auto = None
    if "grid_auto" in f:
        try:
            grid_auto = json.loads(_decoded(f["grid_auto"][()]))
        except (TypeError, ValueError):
            raise InputError(path, "grid_auto", "not a JSON record") from None
        if not isinstance(grid_auto, dict) or not isinstance(grid_auto.get("bound"), float):
            raise InputError(path, "grid_auto", "must be a JSON object with a bound")
    reverse = None
    if "reverse" in f:
        rd = _read_datasets(f, path, _REVERSE, _SOLUTION)
        reverse = _solution(f, path, _REVERSE, {**d, **rd}, n)
    _verify(f, path)  # after the structure, so that a missing dataset is named as such
    check_meaning(path, attrs, d)
    check_feasible_finite(path, d, tilt, speed, xi)
    common = (xi, speed, d["axes/xi_dot"], tilt)
    rest = (d["weights/Q"], d["weights/R"])
    if reverse is not None:
        check_feasible_finite(path, {**d, **rd}, tilt, speed, xi, _REVERSE)
        reverse = _table(common, reverse, rest, d, attrs, f"{path} ({_REVERSE})", None, None)
    return _table(common, s, rest, d, attrs, str(path), grid_auto, reverse)


def _read_datasets(f, path, prefix: str, keys: dict) -> dict:
    """The datasets ``keys`` (name -> allowed ndims) under ``prefix``, by their names
    without it; InputError naming the first missing one or one of the wrong rank."""
    d = {}
    for key, ndim in keys.items():
        if prefix + key not in f:
            raise InputError(path, prefix + key, "missing dataset")
        v = f[prefix + key][()]
        if np.ndim(v) not in np.atleast_1d(ndim):
            want = " or ".join(map(str, np.atleast_1d(ndim)))
            raise InputError(path, prefix + key,
                             f"must have {want} dimensions, has {np.ndim(v)}")
        d[key] = _decoded(v)
    return d


def _solution(f, path, prefix: str, d: dict, n: int) -> dict:
    """The solved grid under ``prefix`` (the root's, or ``reverse/``), checked against the
    axes of ``d``: its arrays by their names without the prefix, the attitude offsets
    (``"offsets"``, None without) and the closed-loop modes (``"modes"``, {} without)."""
    n_xi, n_v, n_a = d["axes/xi"].size, d["axes/speed"].size, d["axes/tilt"].size
    K0 = d["gains/K_tilt0"]
    shapes = {
        "gains/K_tilt0": (n_v, 4, n) if K0.ndim == 3 else (n_v, n_xi, 4, n),
        "gains/K": (n_a - 1, n_v, n_xi, 4, n),
        "nominal/u_d": (n_a, n_v, n_xi, 4), "nominal/phi_d": (n_a, n_v, n_xi),
        "nominal/tension": (n_a, n_v, n_xi), "feasibility/reasons": (n_a, n_v, n_xi),
        "closed_loop/spectral_radius": (n_a, n_v), "weights/Q": (n, n), "weights/R": (4, 4),
        "axes/xi_dot": (n_v,), "closed_loop/dt": (n_v,),
    }
    for key, shape in shapes.items():
        if d[key].shape != shape:
            where = prefix + key if key in _SOLUTION else key
            raise InputError(path, where, f"shape {d[key].shape} does not match the axes {shape}")
    offsets = None
    if prefix + "nominal/attitude_offsets" in f:
        offsets = np.asarray(f[prefix + "nominal/attitude_offsets"][()], dtype=float)
        nb = offsets.shape[-1] if offsets.ndim == 4 else 0
        if offsets.shape != (n_a, n_v, 2, nb) or nb % 2 != 1 or not np.all(np.isfinite(offsets)):
            raise InputError(path, prefix + "nominal/attitude_offsets",
                             f"shape {offsets.shape} does not match the axes ({n_a}, {n_v}, 2, "
                             "2 H + 1), or not finite")
    modes = {}
    if prefix + "closed_loop/mode_tau" in f:  # tables before the modes have none
        for key in ("mode_tau", "mode_frequency", "mode_damping", "mode_shape"):
            v = f.get(f"{prefix}closed_loop/{key}")
            m = v.shape[-1 if key != "mode_shape" else -2] if v is not None and v.ndim else 0
            want = (n_a, n_v, m) if key != "mode_shape" else (n_a, n_v, m, n)
            if v is None or v.shape != want:
                raise InputError(path, f"{prefix}closed_loop/{key}", "missing, or its shape "
                                 f"does not match the axes {want}")
            modes[key] = np.asarray(v[()], dtype=float)
    record = record_from_datasets(path, d["firmware/vehicle"], d["firmware/state_map"],
                                  d["firmware/controller"], n)
    return {key: d[key] for key in _SOLUTION} | {"offsets": offsets, "modes": modes,
                                                 "record": record,
                                                 "margins": _margins(f, path, prefix, n_a, n_v)}


def _margins(f, path, prefix, n_a, n_v) -> LoopMargins | None:
    """The stored margins (:class:`~gainsched.schedule.margins.LoopMargins` over (tilt,
    speed)), or None in a table built without them."""
    if prefix + "closed_loop/gain_margin" not in f:
        return None
    d = {}
    for key, want in (("gain_margin", (n_a, n_v, 2)), ("input_gain_margin", (n_a, n_v, 4, 2)),
                      ("delay_margin", (n_a, n_v))):
        v = f.get(f"{prefix}closed_loop/{key}")
        if v is None or v.shape != want:
            raise InputError(path, f"{prefix}closed_loop/{key}", "missing, or its shape does "
                             f"not match the axes {want}")
        d[key] = np.asarray(v[()], dtype=float)
    g, i, w = d["gain_margin"], d["input_gain_margin"], f.get(f"{prefix}closed_loop/crossover")
    if w is not None and w.shape != (n_a, n_v):
        raise InputError(path, f"{prefix}closed_loop/crossover", f"its shape {w.shape} does "
                         f"not match the axes {(n_a, n_v)}")
    return LoopMargins(g[..., 0], g[..., 1], i[..., 0], i[..., 1], d["delay_margin"],
                       None if w is None else np.asarray(w[()], dtype=float))


def _table(axes, s, weights, d, attrs, source, grid_auto, reverse) -> Table:
    """A :class:`Table` of the ``axes``, the solution ``s`` (:func:`_solution`) and the
    root's ``weights``, config and attributes."""
    return Table(
        *axes, s["gains/K_tilt0"], s["gains/K"], s["nominal/u_d"], s["nominal/phi_d"],
        s["nominal/tension"], s["feasibility/reasons"].astype(np.uint8),
        s["closed_loop/spectral_radius"], *weights, s["closed_loop/dt"],
        str(d["config_text"]), str(attrs.get("config_sha256", "")), attrs, source,
        s["offsets"], **s["modes"], grid_auto=grid_auto, firmware=s["record"],
        reverse=reverse, loop_margins=s["margins"],
    )
