"""Test support shared by every test folder: the repository's paths, the tools found on
this machine, and the config factory.

``tests/conftest.py`` turns these into fixtures and markers; a test module imports from
here only what it needs at collection time (paths in ``parametrize`` lists, say). The
folder ``tests/`` is on ``sys.path`` (pytest puts the root conftest's folder there), so
``from support import ...`` works from every test folder.
"""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

import numpy as np
import tomlkit

from gainsched import native
from gainsched.config import Config, config_from_text, set_values
from gainsched.firmware.host.pil import pil_tools
from gainsched.schedule.onboard import record_from_config
from gainsched.schedule.tables import Table

REPO = Path(__file__).resolve().parents[1]
PAPER_TOML = REPO / "configs" / "paper.toml"
PAPER_H5 = REPO / "tables" / "paper.h5"

#: the host C compiler (``$CC``, cc, gcc, clang), or None: tests marked ``needs_cc`` skip
CC = native.find_cc()
#: the Cortex-M4F cross compiler and QEMU, or None: tests marked ``needs_arm`` skip
ARM_TOOLS = pil_tools()

#: the open-loop reference circle of the link-model tests (the ``circle`` fixture): m/s, rad
CIRCLE_SPEED, CIRCLE_TILT = 8.0, np.deg2rad(20.0)

#: what ``small_config`` changes in configs/paper.toml unless told otherwise: 2 speeds x
#: 2 tilts x 8 azimuths, a table built in about a second
SMALL_GRID = {
    "name": "small",
    "grid.speeds": [6, 9],
    "grid.tilts_deg": [0, 20],
    "grid.azimuth_samples": 8,
}


def _dotted(keys: dict) -> dict:
    """``grid__speeds`` -> ``grid.speeds``; dotted keys pass as they are."""
    return {k.replace("__", "."): v for k, v in keys.items()}


def small_config_text(**keys) -> str:
    """The text of configs/paper.toml on the small grid, with ``keys`` set on top.

    Keys are dotted config keys, written with ``__`` for the dot as keyword arguments
    (``grid__speeds=[3, 9]``, ``control__azimuth_integral=True``) or passed as a dict
    (``**{"effects.motor_lag.tau": 0.03}``); a value of None keeps the paper's value of
    a key the small grid sets (``grid__speeds=None``: the paper's speeds). The text is
    edited with :func:`gainsched.config.set_values`, so comments and layout are kept,
    and it is not validated: a test of a refusal writes the bad value this way.
    """
    values = {**SMALL_GRID, **_dotted(keys)}
    return set_values(PAPER_TOML.read_text(), {k: v for k, v in values.items() if v is not None})


def small_config(**keys) -> Config:
    """:func:`small_config_text`, validated: a :class:`gainsched.config.Config` whose
    source is ``<name>.toml``."""
    name = _dotted(keys).get("name", SMALL_GRID["name"])
    return config_from_text(small_config_text(**keys), f"{name}.toml")


def paper_config_text(**keys) -> str:
    """The text of configs/paper.toml (its own grid) with ``keys`` set, as
    :func:`small_config_text` sets them."""
    return set_values(PAPER_TOML.read_text(), _dotted(keys)) if keys else PAPER_TOML.read_text()


#: what ``gainsched improve configs/paper.toml examples/flights/*.csv`` adds to the paper's
#: model (docs/model-vs-measurement.md), as :func:`paper_config_text` keys
IMPROVED = {"effects.thrust_momentum.disk_area": 0.005986, "effects.motor_lag.tau": 0.02979}


def paper_model(**keys):
    """The reduced model of :func:`paper_config_text` (``paper_model(**{
    "effects.motor_lag.tau": 0.035})``: the paper vehicle with a motor lag), a new one per
    call: the trim's caches are per model."""
    from gainsched.model.reduced import Model

    return Model(config_from_text(paper_config_text(**keys), "paper.toml"))


# --------------------------------------------------------------------------- firmware


def synthetic_table(n_a=4, n_v=5, n_xi=8, *, motor_lag=False, azimuth_integral=False, seed=0,
                    name="synth", tilt0_per_azimuth=False) -> Table:
    """Random gains on a small nonuniform grid, with every kind of infeasible point:
    whole circles without gains (tilt > 0 and tilt 0) and flagged points that keep them.
    ``tilt0_per_azimuth``: tilt-0 gains per azimuth (an effect that changes with it)."""
    rng = np.random.default_rng(seed)
    keys = {"name": name}
    if motor_lag:
        keys["effects.motor_lag.tau"] = 0.03
    if azimuth_integral:  # int_xi after int_delta: 12 LQR states
        keys.update({"control.azimuth_integral": True,
                     "control.Q": [3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5, 1]})
    text = paper_config_text(**keys)
    n = 11 + int(azimuth_integral) + (4 if motor_lag else 0)
    r = 1.6
    speed = np.array([2.0, 3.5, 4.0, 7.0, 11.0, 12.5, 15.0][:n_v])
    tilt = np.deg2rad([0.0, 12.0, 25.0, 40.0, 55.0][:n_a])
    K0 = rng.normal(size=(n_v, n_xi, 4, n) if tilt0_per_azimuth else (n_v, 4, n))
    K = rng.normal(size=(n_a - 1, n_v, n_xi, 4, n))
    u_d = rng.uniform(0.2, 3.0, size=(n_a, n_v, n_xi, 4))
    phi_d = rng.uniform(-1.0, 1.0, size=(n_a, n_v, n_xi))
    reasons = np.zeros((n_a, n_v, n_xi), dtype=np.uint8)
    if n_a >= 3 and n_v >= 4:
        K[1, 3] = np.nan  # circle (tilt 2, speed 3) has no gains
        reasons[2, 3] = 16
        reasons[2, 3, :2] = 1
        reasons[1, 1, 2] = 2  # flagged, gains kept
        reasons[n_a - 1, 0, n_xi - 1] = 4
    if n_v >= 5:
        K0[4] = np.nan  # tilt 0 circle without gains
        reasons[0, 4] = 1
    return Table(
        xi=2 * np.pi * np.arange(n_xi) / n_xi,
        speed=speed,
        xi_dot=speed / r,
        tilt=tilt,
        K_tilt0=K0,
        K=K,
        u_d=u_d,
        phi_d=phi_d,
        tension=np.ones((n_a, n_v, n_xi)),
        reasons=reasons,
        spectral_radius=np.full((n_a, n_v), 0.5),
        Q=np.eye(n),
        R=np.eye(4),
        dt=np.full(n_v, 1e-3),
        config_text=text,
        config_sha256="0" * 64,
        attrs={
            "config_name": name,
            "radius_m": r,
            "rate_hz": 1000.0,
            "tool_version": "test",
            "state_names": ",".join(f"s{i}" for i in range(n)),
        },
        source=f"<{name}>",
        firmware=record_from_config(config_from_text(text, f"<{name}>")),
    )


def query_mix(d, m, seed=0):
    """``m`` queries (xi, xi_dot, alpha), float64, in eight equal families: uniform over and
    beyond the table, exact grid values, the tilt-0 slice, table edges +- ulps, the snap
    band at cell faces, out of range, invalid (NaN/inf/beyond the limits), far wraps."""
    rng = np.random.default_rng(seed)
    vmax, amax = float(d.xi_dot[-1]), float(d.tilt[-1])
    k = m // 8
    sign = lambda n: rng.choice([-1.0, 1.0], n)  # noqa: E731
    uni_x = lambda n: rng.uniform(-4 * np.pi, 4 * np.pi, n)  # noqa: E731
    uni_v = lambda n: sign(n) * rng.uniform(0, 1.2 * vmax, n)  # noqa: E731
    uni_a = lambda n: sign(n) * rng.uniform(0, 1.2 * amax + 0.01, n)  # noqa: E731

    def ulps(x, n):
        x = np.asarray(x, dtype=np.float32)
        steps = rng.integers(-3, 4, n)
        out = x.copy()
        for s in (-1, 1):
            for _ in range(3):
                sel = steps * s > 0
                out[sel] = np.nextafter(out[sel], np.float32(s * np.inf))
                steps = steps - s * sel
        return out.astype(np.float64)

    fam = []
    fam.append((uni_x(k), uni_v(k), uni_a(k)))
    fam.append(
        (
            rng.choice(d.xi, k) + 2 * np.pi * rng.integers(-2, 3, k),
            sign(k) * rng.choice(d.xi_dot, k),
            sign(k) * rng.choice(d.tilt, k),
        )
    )
    fam.append((uni_x(k), uni_v(k), rng.choice([0.0, -0.0], k)))
    edge_v = rng.choice(np.r_[d.xi_dot[[0, -1]], d.xi_dot], k)
    edge_a = rng.choice(np.r_[d.tilt[[0, -1]], d.tilt], k)
    edge_x = rng.choice(np.r_[0.0, np.pi, 2 * np.pi, -np.pi, d.xi], k)
    fam.append((ulps(edge_x, k), sign(k) * ulps(edge_v, k), sign(k) * ulps(edge_a, k)))
    # within ~2^-12 of a cell face: the snap band and its borders
    dv = np.diff(d.xi_dot.astype(float)) if d.xi_dot.size > 1 else np.ones(1)
    da = np.diff(d.tilt.astype(float)) if d.tilt.size > 1 else np.ones(1)
    band = lambda n: rng.choice([-1, 1], n) * 2.0**-12 * rng.uniform(0.5, 1.5, n)  # noqa: E731
    iv, ia = rng.integers(0, dv.size, k), rng.integers(0, da.size, k)
    fam.append(
        (
            rng.choice(d.xi, k) + band(k) * 2 * np.pi / d.xi.size,
            sign(k) * np.abs(d.xi_dot[iv] + band(k) * dv[iv]),
            sign(k) * np.abs(d.tilt[ia] + band(k) * da[ia]),
        )
    )
    fam.append(
        (
            uni_x(k),
            sign(k) * rng.choice([0.0, 0.5 * float(d.xi_dot[0]), 1.5 * vmax, 999.0], k),
            sign(k) * rng.uniform(amax, np.pi / 2, k),
        )
    )
    bad = np.array([np.nan, np.inf, -np.inf, 1e4 * 1.001, -2e4, 1e30, 3e38, 1e300])
    bx, bv, ba = uni_x(k), uni_v(k), uni_a(k)
    which = rng.integers(0, 3, k)
    pick = rng.choice(bad, k)
    bx = np.where(which == 0, pick, bx)
    bv = np.where(which == 1, np.where(np.isfinite(pick), pick / 10, pick), bv)
    ba = np.where(which == 2, np.where(np.isfinite(pick), np.pi / 2 + np.abs(pick) / 1e4, pick), ba)
    fam.append((bx, bv, ba))
    rest = m - 7 * k
    fam.append((rng.uniform(-1e4, 1e4, rest), uni_v(rest), sign(rest) * rng.uniform(0, amax, rest)))
    x, v, a = (np.concatenate(c) for c in zip(*fam, strict=True))
    return x, v, a


#: examples/firmware: the example firmware and the fuzz drivers
FIRMWARE_EXAMPLES = REPO / "examples" / "firmware"
#: the environment of a program built with AddressSanitizer and UBSan: stop at the first error
SAN_ENV = {
    **os.environ,
    "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0:halt_on_error=1",
    "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1",
}


def sigint_default():
    """``preexec_fn`` of a child that must see a Ctrl-C as a terminal delivers it: a runner
    that started the suite in the background (a shell without job control, CI) hands its
    children SIGINT ignored, which Python then keeps, and an injected Ctrl-C would never
    arrive."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def compile_c(args, cwd=None):
    """Run the host C compiler (``CC``) with ``args``; it must succeed without a warning."""
    res = subprocess.run([CC, *args], capture_output=True, text=True, cwd=cwd)
    assert res.returncode == 0, res.stderr
    assert "warning" not in res.stderr, res.stderr


def sanitizers_work(tmp_path) -> bool:
    """True if the host C compiler links a program with AddressSanitizer and UBSan."""
    src = tmp_path / "probe.c"
    src.write_text("int main(void) { return 0; }\n")
    res = subprocess.run(
        [CC, "-fsanitize=address,undefined", str(src), "-o", str(tmp_path / "probe")],
        capture_output=True,
    )
    return res.returncode == 0


# --------------------------------------------------------------------------- chosen axes

#: the automatic axes of :func:`auto_text` (issue 23): the build chooses the breakpoints
AUTO_SPEEDS = {"min": 6, "max": 12, "max_count": 9}
AUTO_TILTS = {"min": 0, "max": 30, "max_count": 9}


def toml_range(value):
    """``value`` as a config value: a dict as an inline table (``{min = 6, max = 12}``,
    the range syntax of docs/grid.md; :func:`small_config_text` would write a dict as a
    ``[section]``), anything else as it is."""
    if not isinstance(value, dict):
        return value
    table = tomlkit.inline_table()
    table.update(value)
    return table


def auto_text(speeds=AUTO_SPEEDS, tilts=AUTO_TILTS, n_xi=16, bound=3, name="auto"):
    """:func:`small_config_text` with ranges for the axes (a list: the breakpoints
    themselves), ``n_xi`` azimuth samples (a dict: a range) and the interpolation bound
    ``bound`` percent."""
    return small_config_text(name=name, grid__speeds=toml_range(speeds),
                             grid__tilts_deg=toml_range(tilts),
                             grid__azimuth_samples=toml_range(n_xi),
                             grid__max_interpolation_error=bound)


# --------------------------------------------------------------------------- campaigns

#: s, the flight time of the campaigns the analysis tests fly (conftest ``fly``)
CAMPAIGN_DURATION = 2.5

#: the default flights a campaign with an effect outside the library (the azimuth thrust
#: loss) flies in the suite: three circles, which its diagnosis needs
OUTSIDE_FLIGHTS = ("v9", "tilt20-v8", "v15")


def once(folder: Path, key, make):
    """``make()``, computed once per test run however many test processes ask: the first
    to ask for ``key`` (any value whose ``repr`` names it: dataclasses, tuples, floats)
    computes it and leaves it pickled in ``folder`` (the ``shared_dir`` fixture); the
    others wait on its lock and read it. For deterministic, expensive test data (a
    flown campaign: test modules on two workers ask for the same ones)."""
    import fcntl
    import hashlib
    import pickle

    name = hashlib.sha256(repr(key).encode()).hexdigest()[:24]
    path = folder / f"{name}.pkl"
    with open(folder / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if path.exists():
            with open(path, "rb") as f:
                return pickle.load(f)
        value = make()
        tmp = path.with_suffix(".part")
        with open(tmp, "wb") as f:
            pickle.dump(value, f, protocol=pickle.HIGHEST_PROTOCOL)
        tmp.replace(path)
        return value


# --------------------------------------------------------------------------- foreign logs


def write_ulog(path, topics: dict, params: dict | None = None) -> None:
    """Write a PX4 ULog with pyulog's own writer (``ULog.write_ulog``), built from arrays.

    ``topics`` maps a topic name to its fields in the log's order: ``"timestamp"``
    (microseconds, written uint64) first, then float32 fields, ``"q[0]"``.. ``"q[3]"``
    written as one ``float[4] q`` field; ``params`` the initial parameters (float or
    int). pyulog has no builder API, so the reader's own classes are filled as its
    parser fills them; its writer then writes every message.
    """
    import struct

    from pyulog import ULog

    ulog = ULog(None)
    ulog._file_version = 1
    ulog._start_timestamp = int(min(int(f["timestamp"][0]) for f in topics.values()))
    for name, fields in topics.items():
        parts: list[str] = []
        for key in fields:
            base, _, rest = key.partition("[")
            if not rest:
                parts.append(f"{'uint64_t' if key == 'timestamp' else 'float'} {key};")
            elif rest == "0]":
                n = sum(1 for k in fields if k.startswith(base + "["))
                parts.append(f"float[{n}] {base};")
        ulog._message_formats[name] = ULog.MessageFormat(
            f"{name}:{''.join(parts)}".encode(), None)
    for msg_id, (name, fields) in enumerate(topics.items()):
        add = ULog._MessageAddLogged(struct.pack("<BH", 0, msg_id) + name.encode(), None,
                                     ulog._message_formats)
        rec = np.zeros(len(fields["timestamp"]), dtype=add.dtype)
        for fd in add.field_data:
            rec[fd.field_name] = fields[fd.field_name]
        add.buffer = bytearray(rec.tobytes())
        ulog._data_list.append(ULog.Data(add))
    ulog._initial_parameters = dict(params or {})
    ulog.write_ulog(str(path))


def write_bag(path, messages: dict, storage: str = "mcap") -> None:
    """Write a ROS 2 bag (rosbag2, ``"mcap"`` or ``"sqlite3"`` storage) with rosbags'
    writer: ``messages`` maps a topic to ``(msgtype, [(t_ns, message), ...])``, the
    messages built from the standard type store (:func:`ros_types`)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = ros_types()
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9 if storage == "mcap" else 8, storage_plugin=plugin) as w:
        items = []
        for topic, (msgtype, msgs) in messages.items():
            conn = w.add_connection(topic, msgtype, typestore=store)
            items += [(t, conn, msgtype, m) for t, m in msgs]
        for t, conn, msgtype, m in sorted(items, key=lambda x: x[0]):
            w.write(conn, int(t), store.serialize_cdr(m, msgtype))


def ros_types():
    """rosbags' type store of the latest ROS 2 LTS (its message classes by name)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.LATEST)


def recorded_rows(res, *, every=5, delay=12, rng=None, bad=()):
    """A flight's sensor inputs (a SimResult) as the firmware gets them, shape (m, N_INPUT):
    poses every `every` steps, arriving `delay` steps late, with noise; the gyro and the
    accelerometer every step; `bad`: (step, column, value) written over them."""
    from gainsched.firmware.controller import FLAG_ACCEL, FLAG_POSE, N_INPUT

    rng = rng or np.random.default_rng(0)
    n = res.t.size
    rows = np.zeros((n, N_INPUT))
    pend = []
    xi = (res.z_d[:, 1] + np.pi) % (2 * np.pi) - np.pi
    for k in range(n):
        flags = FLAG_ACCEL
        if k % every == 0:
            pend.append((k + delay, res.p_I[k] + 5e-4 * rng.standard_normal(3), res.q_IB[k]))
        if pend and pend[0][0] <= k:
            _, p, q = pend.pop(0)
            flags |= FLAG_POSE
            rows[k, 1:4], rows[k, 4:8] = p, q
        rows[k, 0] = flags
        rows[k, 11:14] = res.z[k, 7:10] + 0.003 * rng.standard_normal(3)
        rows[k, 14:17] = res.f_B[k] + 0.05 * rng.standard_normal(3)
        rows[k, 17], rows[k, 18] = xi[k], res.z_d[k, 3]
        rows[k, 22], rows[k, 23] = res.scenario.tilt, res.scenario.gamma
    for k, col, value in bad:
        rows[k, col] = value
    return rows


def on_terminal(args, cwd, *, columns: int = 100, timeout: float = 300) -> tuple[int, str]:
    """Run ``args`` with stderr on a pseudo-terminal of ``columns`` columns (tqdm draws
    nothing on a terminal of 0 columns, what a bare ``openpty`` reports) and stdout on a
    pipe: ``(exit code, everything the terminal showed)``."""
    import fcntl
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=slave, cwd=cwd)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        chunks.append(chunk)
    p.wait(timeout=timeout)
    os.close(master)
    return p.returncode, b"".join(chunks).decode(errors="replace")


#: issue 53: hidden effects flown on the elastic tether of a real vehicle (REAL_TETHER, k =
#: 2e5 N/m, which stretches ~0.3 mm at the highest tensions): the physical effect named
#: (with the tether's own stretch beside it, or alone), its parameter within 10 % of the
#: effect's size, the held-out residual above noise falling >= 80 %. Before the
#: nuisance fit (gainsched/analysis/diagnose/_diagnose.py) a thrust scale was taken for
#: the empirical thrust_azimuth, a battery sag for thrust_time_series, and the negative
#: control found nothing although the tether stretched.
REAL_TETHER_CASES = {
    # hidden: (candidate, parameter, truth, the parameter's value without the effect)
    "thrust_scale": ("thrust_scale", "k_T", 0.92, 1.0),
    "rotor_drag": ("rotor_drag", "k_rd", 0.015, 0.0),
    "thrust_time": ("thrust_time", "rate", 0.016, 0.0),
    "motor_lag": ("motor_lag", "tau", 0.035, 0.0),
    # what every real quadcopter has: the moments of inertia and the rotors' reaction
    # torque known to tens of percent (the yaw inertia alone is seen on circles only
    # through Jzz - Jyy, and reported as inertia_y's twin: test_the_yaw_inertia_...)
    "inertia_x": ("inertia_x", "Jxx", 3.25e-3, 2.5e-3),
    "kappa": ("kappa", "kappa", 0.024, 0.016),
    # the centre of mass 3 mm to the right of the frame centre, 2 mm below it (the tether
    # yaws and pitches the vehicle about it: test_a_centre_of_mass_off_the_frame_...)
    "cog_offset": ("cog_offset", "y", 0.003, 0.0),
    # the rest of the library's physical effects (the whole suite, issue 53)
    "drag_quadratic": ("drag_quadratic", "mu2", 0.0075, 0.0025),
    "drag_both": ("drag", "mu2", 0.0045, 0.0025),
    "thrust_airspeed": ("thrust_airspeed", "c1", -0.01, 0.0),
    "thrust_momentum": ("thrust_momentum", "disk_area", 0.006, 0.0),
    "latency": ("latency", "latency_s", 0.015, 0.0),
    "motor_efficiency": ("motor_efficiency", "eta3", 0.92, 1.0),
    "battery": ("thrust_voltage", "exponent", 2.0, 0.0),
    "wind": ("wind", "east", 2.4, 0.0),
    "mass": ("mass", "mass", 0.55, 0.5),
}


#: the cases of REAL_TETHER_CASES checked in tests/analysis/test_real_tether.py, on its own
#: campaigns; tests/analysis/test_diagnose.py checks the others on the campaigns it
#: diagnoses anyway (the same default flights on the same tether: flown once)
REAL_TETHER_OWN = ("inertia_x", "kappa", "cog_offset", "thrust_momentum", "wind")


def assert_named_on_the_real_tether(paper_config, d, hidden: str) -> None:
    """Issue 53's check of a diagnosis ``d`` of the campaign with ``hidden`` flown on the
    real tether (:data:`REAL_TETHER_CASES`): the physical effect named, with at most the
    tether's stretch beside it (its stiffness within 15 %), no empirical term, its
    parameter within 10 % of the effect's size, the held-out residual above noise falling
    >= 80 %, no axis worse; --apply writes a vehicle parameter in [vehicle]."""
    import pytest

    from gainsched.analysis.diagnose import apply_candidate
    from gainsched.config import config_from_text

    name, param, true, none = REAL_TETHER_CASES[hidden]
    a = d.accepted
    assert a is not None, d.verdict
    parts = set(a.name.split(" + "))
    assert name in parts and parts <= {name, "tether_elasticity"}, d.verdict
    assert "empirical" not in d.verdict
    assert abs((a.values[param] - none) / (true - none) - 1) <= 0.10, (a.values, true)
    if "tether_elasticity" in parts:
        assert a.values["stiffness"] == pytest.approx(2e5, rel=0.15)
    assert excess_rms_fall(a) >= 0.8, a.excess_explained
    assert not a.worse_axes()
    new = config_from_text(apply_candidate(paper_config, a), "fitted.toml")
    written = {"inertia_x": lambda c: c.vehicle.inertia[0, 0], "kappa": lambda c: c.vehicle.kappa}
    if name in written:  # a vehicle parameter: --apply writes it in [vehicle]
        assert written[name](new) == pytest.approx(a.values[param], rel=1e-12)


def story(result) -> str:
    """The name of a diagnose fit (a ``CandidateResult``; "" for None) without the real
    tether's own stretch beside it: the campaigns fly on the elastic tether of a real
    vehicle (``conftest.fly``), whose stretch diagnose fits as a nuisance with whatever
    else is missing (``tether_elasticity``), so ``story(d.accepted)`` is what a test's
    hidden effect should be named."""
    if result is None:
        return ""
    parts = [p for p in result.name.split(" + ") if p != "tether_elasticity"]
    return " + ".join(parts) or result.name


def physical(result) -> bool:
    """Whether a diagnose fit tells a physical story beyond the tether's own stretch: a
    part of it that is neither an empirical law nor ``tether_elasticity``."""
    parts = getattr(result.candidate, "parts", None) or (result.candidate,)
    return any(not getattr(p, "empirical", False) and p.name != "tether_elasticity"
               for p in parts if p is not None)


def excess_rms_fall(result) -> float:
    """Held-out fall of the residual RMS above the noise floor of a diagnose fit (a
    CandidateResult): ``1 - sqrt(1 - excess_explained)``."""
    return 1 - float(np.sqrt(max(0.0, 1 - result.excess_explained)))


def rechecksum(f) -> None:
    """Recompute the checksums of an open table file ``f`` (h5py, writable) after an
    edit: what a tool that "repairs" them would do, so that the check after the
    checksums is the one a test reaches."""
    from gainsched.schedule.h5io import dataset_sha256, datasets, root_sha256

    digests = {}
    for name, ds in datasets(f).items():
        digests[name] = ds.attrs["sha256"] = dataset_sha256(ds[()])
    f.attrs["data_sha256"] = root_sha256(dict(f.attrs), digests)


def run_examples(obj, name: str, folder, monkeypatch) -> None:
    """Run the Examples of ``obj``'s docstring (doctest, ``gs`` and ``np`` given, ellipsis
    and whitespace as written) in ``folder`` (a working directory like the repository
    root); a result class without one (a dataclass) passes. Fails naming ``name``."""
    import dataclasses
    import doctest

    import gainsched

    tests = doctest.DocTestFinder(recurse=False).find(
        obj, name, globs={"gs": gainsched, "np": np})
    examples = [t for t in tests if t.examples]
    if not examples:
        assert dataclasses.is_dataclass(obj), f"{name} has no Example"
        return
    monkeypatch.chdir(folder)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for t in examples:
        runner.run(t)
    failed, attempted = runner.summarize(verbose=False)
    assert attempted > 0
    assert failed == 0, f"{name}: {failed} of {attempted} example lines failed (output above)"


def text_problems(fig) -> list[tuple]:
    """What makes a figure hard to read at its saved size: each text (titles, labels,
    tick and colorbar labels, the values printed in cells) drawn partly outside the
    figure (``("cut", text)``), and each pair of texts whose boxes overlap by more than a
    pixel (``("overlap", text, text)``). Empty: legible."""
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    hidden = set()  # the labels of ticks outside the view: matplotlib keeps, never draws them
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if not lo - 1e-9 * (hi - lo) <= tick.get_loc() <= hi + 1e-9 * (hi - lo):
                    hidden.update({id(tick.label1), id(tick.label2)})
    texts = [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()
             and id(t) not in hidden]
    boxes = np.array([t.get_window_extent(renderer).extents for t in texts]).reshape(-1, 4)
    W, H = fig.canvas.get_width_height()
    out = [("cut", t.get_text()) for t, b in zip(texts, boxes, strict=True)
           if b[0] < -1 or b[1] < -1 or b[2] > W + 1 or b[3] > H + 1]
    x = np.clip(np.minimum(boxes[:, None, 2], boxes[None, :, 2])
                - np.maximum(boxes[:, None, 0], boxes[None, :, 0]), 0, None)
    y = np.clip(np.minimum(boxes[:, None, 3], boxes[None, :, 3])
                - np.maximum(boxes[:, None, 1], boxes[None, :, 1]), 0, None)
    i, j = np.nonzero(np.triu(x * y > 1.0, k=1))
    return out + [("overlap", texts[a].get_text(), texts[b].get_text())
                  for a, b in zip(i, j, strict=True)]
