"""What a gain table's checksums cannot vouch for, checked when it is loaded
(:func:`gainsched.schedule.tables.load_table`): the root attributes against the config
keys they come from and the embedded config, and finite values at every feasible point
(docs/table-format.md, "Integrity")."""

from __future__ import annotations

import hashlib
import math

import numpy as np

from ..config import MAX_RATE_HZ, MAX_TETHER_LENGTH, TERMINAL_COSTS, check_name
from ..errors import InputError
from ..textinput import parse_toml

__all__ = ["check_meaning", "check_feasible_finite"]


def _number_attr(path, attrs, key, lo, hi, unit) -> float:
    """A root attribute that must be a finite number in ``(lo, hi]``, as the config key."""
    v = attrs[key]
    if isinstance(v, bool | str | bytes) or np.ndim(v) != 0:
        raise InputError(path, key, f"must be a number, got {v!r:.40}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(path, key, f"must be a number, got {v!r:.40}") from None
    if not (math.isfinite(x) and lo < x <= hi):
        raise InputError(path, key, f"must be in ({lo:g}, {hi:g}] {unit}, got {x:g}")
    return x


def check_meaning(path, attrs, d) -> None:
    """What the checksums cannot vouch for (a hand edit with the checksums recomputed):
    the root attributes range-checked as the config keys they come from, ``config_sha256``
    the SHA-256 of ``config_text``, the text TOML, and the attributes it determines
    (``rate_hz``, ``radius_m``, ``terminal``, ``config_name``) equal to its values."""
    rate = _number_attr(path, attrs, "rate_hz", 0.0, MAX_RATE_HZ, "Hz")
    radius = _number_attr(path, attrs, "radius_m", 0.0, 2 * MAX_TETHER_LENGTH, "m")
    terminal = str(attrs["terminal"])
    if terminal not in TERMINAL_COSTS:
        raise InputError(path, "terminal", f"must be one of {', '.join(TERMINAL_COSTS)}; got "
                         f"{terminal!r:.40}")
    check_name(path, str(attrs["config_name"]))
    if not np.allclose(d["axes/xi_dot"], d["axes/speed"] / radius, rtol=1e-12, atol=0):
        raise InputError(path, "radius_m", f"{radius:g} m is not the radius of the axes "
                         "(axes/xi_dot = axes/speed / radius_m)")
    dt = d["closed_loop/dt"]
    if not np.all(np.isfinite(dt) & (dt > 0)):
        raise InputError(path, "closed_loop/dt", "must be finite and > 0")
    text = d["config_text"]
    text = text.decode("utf-8", "replace") if isinstance(text, bytes) else str(text)
    want = hashlib.sha256(text.encode()).hexdigest()
    if str(attrs["config_sha256"]) != want:
        raise InputError(path, "config_sha256", f"{str(attrs['config_sha256'])[:12]}... is not "
                         f"the SHA-256 of config_text ({want[:12]}...): the embedded config "
                         "is not the one the table was built from; rebuild the table")
    try:
        cfg = parse_toml(text, path)
    except InputError as exc:
        raise InputError(path, "config_text", f"the embedded config {exc.message}") from None
    # the attributes the embedded config determines (its full validation: table_config)
    tether, control = cfg.get("tether"), cfg.get("control")
    if isinstance(control, dict) and _is_number(control.get("rate_hz")):
        if float(control["rate_hz"]) != rate:
            raise InputError(path, "rate_hz", f"{rate:g} Hz, but the embedded config's "
                             f"control.rate_hz is {float(control['rate_hz']):g}")
    if isinstance(control, dict) and control.get("terminal", "periodic") != terminal:
        raise InputError(path, "terminal", f"{terminal!r}, but the embedded config's "
                         f"control.terminal is {control.get('terminal', 'periodic')!r:.40}")
    if (isinstance(tether, dict) and _is_number(tether.get("length"))
            and _is_number(tether.get("attachment_offset"))):
        r = float(tether["length"]) + float(tether["attachment_offset"])
        if r != radius:
            raise InputError(path, "radius_m", f"{radius:g} m, but the embedded config's "
                             f"tether.length + attachment_offset is {r:g} m")
    if "name" in cfg and cfg["name"] != str(attrs["config_name"]):
        raise InputError(path, "config_name", f"{str(attrs['config_name'])!r}, but the "
                         f"embedded config's name is {cfg['name']!r:.70}")


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def check_feasible_finite(path, d, tilt, speed, xi, prefix: str = "") -> None:
    """Gains, nominal thrusts and roll must be finite at every feasible point (reasons 0);
    ``prefix``: where the solution ``d`` holds lies in the file (``reverse/``)."""
    ok = d["feasibility/reasons"] == 0  # (n_a, n_v, n_xi)
    checks = (
        ("gains/K_tilt0", d["gains/K_tilt0"], ok[0].any(-1), lambda i: (0, i[0], 0))
        if d["gains/K_tilt0"].ndim == 3 else
        ("gains/K_tilt0", d["gains/K_tilt0"], ok[0], lambda i: (0, i[0], i[1])),
        ("gains/K", d["gains/K"], ok[1:], lambda i: (i[0] + 1, i[1], i[2])),
        ("nominal/u_d", d["nominal/u_d"], ok, tuple),
        ("nominal/phi_d", d["nominal/phi_d"], ok, tuple),
    )
    for key, x, feasible, point in checks:
        extra = x.ndim - feasible.ndim
        bad = feasible & ~np.all(np.isfinite(x), axis=tuple(range(-extra, 0)) if extra else ())
        if np.any(bad):
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            a, v, k = point(idx)
            raise InputError(path, f"{prefix}{key}[{', '.join(map(str, idx))}]",
                             f"non-finite value at a feasible point (tilt "
                             f"{np.rad2deg(tilt[a]):g} deg, speed {speed[v]:g} m/s, azimuth "
                             f"{np.rad2deg(xi[k]):g} deg); the table is corrupt")
