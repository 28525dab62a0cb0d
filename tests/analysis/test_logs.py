"""Flight-log reader/writer (gainsched-flightlog/1)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

from gainsched.analysis.logs import (
    SCHEMA,
    FlightLog,
    LogWarning,
    describe,
    log_bytes,
    log_from_arrays,
    read_log,
    write_log,
)
from gainsched.errors import InputError

DATA = Path(__file__).parent / "data"
META = {"schema": SCHEMA, "alpha_c_deg": "20", "gamma_c_deg": "0", "flight_id": "test"}
N_META = 4  # metadata lines written before the header by _csv_text
REQUIRED = ["t", "x", "y", "z", "qw", "qx", "qy", "qz", "T1", "T2", "T3", "T4"]


def _attitude(R_IC, xi, rng):
    """Quaternions (N, 4) of ``R_IB = R_IC Rz(xi)`` tilted by a small random rotation:
    x_B outward along the tether, z_B along the plane's normal (docs/conventions.md), as
    the reader's consistency checks (gainsched/analysis/logs/_consistency.py) expect of a flight."""
    from scipy.spatial.transform import Rotation

    tilt = Rotation.from_rotvec(rng.normal(0, 0.02, 3))
    R = Rotation.from_matrix(R_IC) * Rotation.from_rotvec(xi[:, None] * [0.0, 0.0, 1.0]) * tilt
    return np.roll(R.as_quat(), 1, axis=1)  # scalar first


def _columns(n=60, seed=0, dt=0.005):
    """A plausible, smooth flight: full-precision random floats, unit quaternions."""
    rng = np.random.default_rng(seed)
    t = 0.37 + dt * np.arange(n) + rng.uniform(-1e-5, 1e-5, n)
    xi = 5.0 * t
    cols = {
        "t": t,
        "x": 1.6 * np.cos(xi) + rng.normal(0, 1e-3, n),
        "y": 1.6 * np.sin(xi) * math.cos(0.35) + rng.normal(0, 1e-3, n),
        "z": 1.6 * np.sin(xi) * math.sin(0.35) + rng.normal(0, 1e-3, n),
    }
    c, s = math.cos(0.35), math.sin(0.35)
    q = _attitude(np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), xi, rng)
    for j, name in enumerate(("qw", "qx", "qy", "qz")):
        cols[name] = q[:, j]
    for j in range(4):
        cols[f"T{j + 1}"] = 1.2 + rng.normal(0, 0.05, n)
    return cols


def _full_columns(n=60, seed=1):
    cols = _columns(n, seed)
    rng = np.random.default_rng(seed + 100)
    for name in ("ax", "ay", "az", "tension"):
        cols[name] = rng.normal(size=n) * 10 ** rng.uniform(-3, 3)
    cols["vbat"] = 12.6 - rng.uniform(0.0, 2.0, n)  # a battery voltage is positive
    # the gyro and the reference azimuth agree with the pose (the reader checks them)
    for name, rate in (("p", 0.0), ("q", 0.0), ("r", 5.0)):
        cols[name] = rate + rng.normal(size=n) * 10 ** rng.uniform(-3, -1)
    cols["xi_ref"] = 5.0 * cols["t"] + rng.normal(size=n) * 1e-3
    cols["xi_dot_ref"] = 5.0 + rng.normal(size=n) * 1e-3
    cols["vbat"][3] = np.nan  # a missing sensor sample is allowed in optional columns
    cols["zz_mode"] = rng.integers(0, 4, n).astype(float)
    cols["aa_debug"] = rng.normal(size=n) * 1e-200
    return cols


def _csv_text(cols, meta=META, order=None):
    order = list(cols) if order is None else order
    lines = [f"# {k}: {v}" for k, v in meta.items()]
    lines.append(",".join(order))
    n = len(next(iter(cols.values())))
    for i in range(n):
        lines.append(",".join(repr(float(cols[c][i])) for c in order))
    return lines


def _write_lines(path, lines):
    path.write_text("\n".join(lines) + "\n")
    return path


def _data_line(i):
    """File line number of 0-based data row i in a file written by _csv_text with META."""
    return N_META + 1 + i + 1


# ---------------------------------------------------------------------------
# round trips


@pytest.mark.parametrize("ext", [".csv", ".h5", ".hdf5"])
def test_round_trip_lossless(tmp_path, ext):
    cols = _full_columns()
    path = tmp_path / f"flight{ext}"
    meta = {**META, "vehicle": "ref-quad", "notes": "a: b, c", "pilot": "x"}
    write_log(path, cols, meta)
    (lg,) = read_log(path)
    assert lg.meta == meta
    assert np.array_equal(lg.t, cols["t"])
    assert np.array_equal(lg.p_I, np.stack([cols[c] for c in "xyz"], 1))
    assert np.array_equal(lg.q, np.stack([cols[c] for c in ("qw", "qx", "qy", "qz")], 1))
    assert np.array_equal(lg.T_cmd, np.stack([cols[f"T{j}"] for j in range(1, 5)], 1))
    assert np.array_equal(lg.optional["omega_B"], np.stack([cols[c] for c in "pqr"], 1))
    assert np.array_equal(lg.optional["f_B"], np.stack([cols[c] for c in ("ax", "ay", "az")], 1))
    for name in ("tension", "vbat", "xi_ref", "xi_dot_ref"):
        assert np.array_equal(lg.optional[name], cols[name], equal_nan=True)
    assert set(lg.extra) == {"zz_mode", "aa_debug"}
    for name in lg.extra:
        assert np.array_equal(lg.extra[name], cols[name])
    # and back again from the FlightLog: same bytes as the first write
    path2 = tmp_path / f"again{ext}"
    write_log(path2, lg)
    (lg2,) = read_log(path2)
    for name, a in lg.columns().items():
        assert np.array_equal(lg2.columns()[name], a, equal_nan=True), name
    assert lg2.meta == lg.meta
    assert list(path.parent.glob(".*.tmp")) == []  # atomic write left no temp file


def test_csv_column_order_and_float_format(tmp_path):
    cols = _full_columns(n=40)
    shuffled = {k: cols[k] for k in np.random.default_rng(3).permutation(list(cols))}
    path = tmp_path / "f.csv"
    write_log(path, shuffled, META)
    lines = path.read_text().splitlines()
    assert lines[0] == f"# schema: {SCHEMA}"
    header = lines[N_META].split(",")
    assert header == [
        *REQUIRED, "p", "q", "r", "ax", "ay", "az", "tension", "vbat", "xi_ref", "xi_dot_ref",
        "aa_debug", "zz_mode",
    ]
    assert lines[N_META + 1].split(",")[0] == repr(float(cols["t"][0]))


def test_hdf5_deterministic_and_layout(tmp_path):
    import time

    cols = _full_columns(n=40)
    a = log_bytes("hdf5", cols, META)
    s = int(time.time())
    while int(time.time()) == s:  # across a wall-clock second: no timestamp in the file
        time.sleep(0.02)
    b = log_bytes("hdf5", cols, META)
    assert a == b
    path = tmp_path / "f.h5"
    write_log(path, cols, META)
    assert path.read_bytes() == a
    with h5py.File(path, "r") as f:
        assert f.attrs["schema"] == SCHEMA
        assert f["t"].shape == (40,) and f["t"].dtype == np.float64


def test_spec_example_parses():
    (lg,) = read_log(DATA / "example.csv")
    assert lg.meta["flight_id"] == "tilt20-v8"
    assert lg.alpha_c == pytest.approx(math.radians(20))
    assert lg.gamma_c == 0.0
    assert len(lg) == 40
    assert lg.t[0] == 0.0 and lg.t[1] == 0.005
    assert np.array_equal(lg.p_I[0], [1.6, 0.0, 0.0])
    assert np.array_equal(lg.T_cmd[0], [1.21, 1.19, 1.22, 1.18])
    # (0.99, 0, 0, 0.12) has norm 0.9972: within tolerance, normalised
    assert np.allclose(np.linalg.norm(lg.q, axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.allclose(lg.q[0], np.array([0.99, 0, 0, 0.12]) / math.hypot(0.99, 0.12))
    assert lg.where(0) == "line 6"
    assert lg.optional == {} and lg.extra == {}
    assert lg.segment == 0 and lg.n_segments == 1 and lg.gaps == ()


def test_shuffled_columns_read_the_same(tmp_path):
    cols = _full_columns()
    order = list(np.random.default_rng(7).permutation(list(cols)))
    (a,) = read_log(_write_lines(tmp_path / "a.csv", _csv_text(cols)))
    (b,) = read_log(_write_lines(tmp_path / "b.csv", _csv_text(cols, order=order)))
    for name, arr in a.columns().items():
        assert np.array_equal(b.columns()[name], arr, equal_nan=True), name
    assert list(a.columns()) == list(b.columns())


def test_unknown_columns_kept(tmp_path):
    cols = _columns(n=40)
    cols["rssi"] = np.arange(40.0)
    cols["motor_temp"] = np.linspace(30, 31, 40)
    for ext in (".csv", ".h5"):
        path = tmp_path / f"u{ext}"
        write_log(path, cols, META)
        (lg,) = read_log(path)
        assert set(lg.extra) == {"rssi", "motor_temp"}
        assert np.array_equal(lg.extra["rssi"], cols["rssi"])
        assert lg.optional == {}


# ---------------------------------------------------------------------------
# bad data: every rule raises InputError naming the file, the column and the row

ROW = 16  # 0-based data row that gets broken


def _mutate(cols, name, value, row=ROW):
    cols = dict(cols)
    cols[name] = np.array(cols[name], dtype=object)
    cols[name][row] = value
    return cols


def _csv_case(case):
    """-> (lines, expected substrings) for one bad-data case."""
    cols = _columns(n=40)
    line = _data_line(ROW)
    if case == "missing column":
        del cols["qy"]
        return _csv_text(cols), ["column qy", "missing"]
    if case == "missing metadata key":
        meta = {k: v for k, v in META.items() if k != "gamma_c_deg"}
        return _csv_text(cols, meta=meta), ["metadata gamma_c_deg", "missing"]
    if case == "wrong schema":
        meta = {**META, "schema": "gainsched-flightlog/2"}
        return _csv_text(cols, meta=meta), ["metadata schema", "gainsched-flightlog/2"]
    if case == "bad alpha":
        meta = {**META, "alpha_c_deg": "twenty"}
        return _csv_text(cols, meta=meta), ["metadata alpha_c_deg", "twenty"]
    if case == "too short":
        cols = {k: v[:20] for k, v in cols.items()}
        return _csv_text(cols), ["column t", f"lines 6-{5 + 20}", "20 samples", "31"]
    lines = _csv_text(cols)
    cells = lines[line - 1].split(",")
    j = {
        "non-numeric cell": "T3",
        "empty cell": "y",
        "NaN": "x",
        "inf": "z",
        "-inf": "T1",
        "time not increasing": "t",
        "time repeated": "t",
        "quaternion norm 0.9": "qw",
        "quaternion zero": "qw",
    }[case]
    col = REQUIRED.index(j)
    expect = [f"column {j}", f"line {line}"]
    if case == "non-numeric cell":
        cells[col] = "1.2.3"
        expect.append("'1.2.3'")
    elif case == "empty cell":
        cells[col] = " "
        expect.append("empty cell")
    elif case == "NaN":
        cells[col] = "nan"
    elif case == "inf":
        cells[col] = "inf"
    elif case == "-inf":
        cells[col] = "-inf"
    elif case == "time not increasing":
        cells[col] = repr(float(cols["t"][ROW - 1]) - 1e-4)
        expect.append("does not increase")
    elif case == "time repeated":
        cells[col] = repr(float(cols["t"][ROW - 1]))
    elif case == "quaternion norm 0.9":
        for c in ("qw", "qx", "qy", "qz"):
            cells[REQUIRED.index(c)] = repr(0.9 * float(cols[c][ROW]))
        expect.append("0.9")
    elif case == "quaternion zero":
        for c in ("qw", "qx", "qy", "qz"):
            cells[REQUIRED.index(c)] = "0"
    lines[line - 1] = ",".join(cells)
    return lines, expect


CSV_CASES = [
    "missing column",
    "missing metadata key",
    "wrong schema",
    "bad alpha",
    "too short",
    "non-numeric cell",
    "empty cell",
    "NaN",
    "inf",
    "-inf",
    "time not increasing",
    "time repeated",
    "quaternion norm 0.9",
    "quaternion zero",
]


@pytest.mark.parametrize("case", CSV_CASES)
def test_csv_bad_data(tmp_path, case):
    lines, expect = _csv_case(case)
    path = _write_lines(tmp_path / "bad.csv", lines)
    with pytest.raises(InputError) as exc:
        read_log(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: "), msg
    assert "\n" not in msg
    for s in expect:
        assert s in msg, (s, msg)
    assert exc.value.exit_code == 2


@pytest.mark.parametrize(
    "edit, expect",
    [
        (lambda L: L.__setitem__(_data_line(5) - 1, L[_data_line(5) - 1] + ",7"), "line 11"),
        (lambda L: L.__setitem__(N_META, L[N_META] + ",t"), "column t, line 5"),
        (lambda L: L.insert(_data_line(5) - 1, "# late: 1"), "line 11"),
        (lambda L: L.__setitem__(slice(None), L[:N_META]), "no header"),
    ],
    ids=["extra cell", "duplicate column", "comment after header", "no header"],
)
def test_csv_structure_errors(tmp_path, edit, expect):
    lines = _csv_text(_columns(n=40))
    edit(lines)
    path = _write_lines(tmp_path / "bad.csv", lines)
    with pytest.raises(InputError, match=expect) as exc:
        read_log(path)
    assert str(exc.value).startswith(f"{path}: ")


@pytest.mark.parametrize(
    "name, value, expect",
    [
        ("x", np.nan, "column x, sample 17"),
        ("T4", np.inf, "column T4, sample 17"),
        ("t", 0.0, "column t, sample 17"),
        ("qz", 5.0, "column qw (quaternion qw,qx,qy,qz), sample 17"),
    ],
)
def test_hdf5_bad_data_names_sample(tmp_path, name, value, expect):
    cols = {k: np.array(v) for k, v in _columns(n=40).items()}
    cols[name][ROW] = value
    path = tmp_path / "bad.h5"
    write_log(path, cols, META)
    with pytest.raises(InputError) as exc:
        read_log(path)
    assert str(exc.value).startswith(f"{path}: {expect}: "), str(exc.value)


def test_hdf5_structure_errors(tmp_path):
    cols = _columns(n=40)
    path = tmp_path / "bad.h5"
    with h5py.File(path, "w") as f:
        for k, v in META.items():
            f.attrs[k] = v
        for k, v in cols.items():
            f[k] = v
        f["x2"] = np.zeros((40, 2))
    with pytest.raises(InputError, match="column x2: must be a 1-D dataset"):
        read_log(path)
    with h5py.File(path, "w") as f:
        for k, v in META.items():
            f.attrs[k] = v
        for k, v in cols.items():
            f[k] = v if k != "T2" else v[:-1]
    with pytest.raises(InputError, match="column T2: has 39 samples"):
        read_log(path)
    with h5py.File(path, "w") as f:
        f.attrs["schema"] = SCHEMA
        f.attrs["alpha_c_deg"] = 20.0  # numeric attributes are accepted
        f.attrs["gamma_c_deg"] = 0
        for k, v in cols.items():
            f[k] = v
        f["mode"] = np.array([b"a"] * 40)
    with pytest.raises(InputError, match="column mode: not numeric"):
        read_log(path)
    path.write_bytes(b"not hdf5 at all")
    with pytest.raises(InputError, match="not a readable HDF5 file"):
        read_log(path)


def test_hdf5_numeric_attributes(tmp_path):
    path = tmp_path / "f.h5"
    with h5py.File(path, "w") as f:
        f.attrs["schema"] = SCHEMA
        f.attrs["alpha_c_deg"] = 20.0
        f.attrs["gamma_c_deg"] = np.int64(-30)
        for k, v in _columns(n=40).items():
            f[k] = v
    (lg,) = read_log(path)
    assert lg.meta["alpha_c_deg"] == "20.0" and lg.meta["gamma_c_deg"] == "-30"
    assert lg.gamma_c == pytest.approx(-math.pi / 6)


@pytest.mark.parametrize("name", ["flight.txt", "flight", "flight.csv.gz"])
def test_unknown_extension(tmp_path, name):
    path = tmp_path / name
    path.write_text("whatever")
    with pytest.raises(InputError, match="unknown log format") as exc:
        read_log(path)
    assert str(exc.value).startswith(str(path))
    with pytest.raises(InputError, match="unknown log format"):
        write_log(path, _columns(n=40), META)


def test_missing_file(tmp_path):
    for ext in (".csv", ".h5"):
        with pytest.raises(InputError, match="cannot read"):
            read_log(tmp_path / f"nope{ext}")


def test_partial_sensor_group(tmp_path):
    cols = _columns(n=40)
    cols["p"] = cols["q"] = np.zeros(40)
    path = tmp_path / "f.csv"
    write_log(path, cols, META)
    with pytest.raises(InputError, match="column r: columns p, q, r go together"):
        read_log(path)


# ---------------------------------------------------------------------------
# normalisation


def test_quaternion_normalised_and_sign_continuous(tmp_path):
    cols = _columns(n=40)
    q = np.stack([cols[c] for c in ("qw", "qx", "qy", "qz")], 1)
    scaled = q * np.linspace(0.995, 1.005, 40)[:, None]  # small deviations: normalised
    flip = np.ones(40)
    flip[10:20] = -1  # q and -q are the same attitude: flipped back
    flip[30] = -1
    scaled *= flip[:, None]
    for j, c in enumerate(("qw", "qx", "qy", "qz")):
        cols[c] = scaled[:, j]
    path = tmp_path / "f.csv"
    write_log(path, cols, META)
    (lg,) = read_log(path)
    assert np.allclose(lg.q, q, rtol=0, atol=1e-15)
    assert np.all(np.sum(lg.q[1:] * lg.q[:-1], axis=1) > 0)


# ---------------------------------------------------------------------------
# gaps and short segments


def test_gap_splits_without_inventing_samples(tmp_path):
    cols = _columns(n=100)
    cols["t"] = cols["t"].copy()
    cols["t"][60:] += 0.05  # a 10-sample dropout after sample 59
    path = tmp_path / "gap.csv"
    write_log(path, cols, META)
    with pytest.warns(LogWarning, match=f"line {_data_line(60)}: gap") as rec:
        logs = read_log(path)
    assert len(rec) == 1
    assert [len(lg) for lg in logs] == [60, 40]
    assert [lg.segment for lg in logs] == [0, 1]
    assert all(lg.n_segments == 2 for lg in logs)
    gap = (float(cols["t"][59]), float(cols["t"][60]))
    assert all(lg.gaps == (gap,) for lg in logs)
    assert logs[0].t[-1] == gap[0] and logs[1].t[0] == gap[1]
    assert np.array_equal(np.concatenate([lg.t for lg in logs]), cols["t"])
    assert np.array_equal(np.concatenate([lg.p_I[:, 0] for lg in logs]), cols["x"])
    assert logs[1].where(0) == f"line {_data_line(60)}"
    text = describe(logs)
    assert "100 samples" in text and "2 of 2 segments kept" in text and "1 gap," in text


def _read_warned(path):
    """``(segments, the LogWarning messages)`` of reading the log at ``path``."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        logs = read_log(path)
    return logs, [str(w.message) for w in rec if issubclass(w.category, LogWarning)]


def test_short_segment_dropped_with_warning(tmp_path):
    cols = _columns(n=80)
    cols["t"] = cols["t"].copy()
    cols["t"][70:] += 0.1  # last piece: 10 samples, too short
    path = tmp_path / "f.h5"
    write_log(path, cols, META)
    logs, msgs = _read_warned(path)
    assert len(msgs) == 2
    assert "gap" in msgs[0] and "sample 71" in msgs[0]
    assert "segment 1 has 10 samples" in msgs[1] and "dropped" in msgs[1]
    assert len(logs) == 1 and len(logs[0]) == 70 and logs[0].n_segments == 2


def test_many_gaps_are_one_line(tmp_path):
    """A day's log with many dropouts (issue 55: 78 warnings, one per gap): up to 3 are
    warned of one by one, more in one line with their count, lengths and the first; the
    segments too short to keep likewise."""
    cols = _columns(n=410)
    cols["t"] = cols["t"].copy()
    for k in range(40, 401, 40):  # 10 gaps of 0.05 s: 10 pieces of 40 samples and one of
        cols["t"][k:] += 0.05  # 10, too short
    path = tmp_path / "day.csv"
    write_log(path, cols, META)
    logs, msgs = _read_warned(path)
    assert len(msgs) == 2 and len(logs) == 10, msgs
    assert "segment 10 has 10 samples" in msgs[1]
    assert msgs[0].startswith(f"{path}: column t: 10 gaps of 0.055-0.055 s (median interval ")
    assert msgs[0].endswith("log split there into 11 segments") and "the first at line " in msgs[0]
    for k in range(0, 40, 5):  # 8 more short pieces: one line for those too
        cols["t"][k + 1:] += 0.05
    write_log(path, cols, META)
    msgs = _read_warned(path)[1]
    assert len(msgs) == 2 and msgs[1].endswith("samples in all; dropped"), msgs


def test_all_segments_too_short_is_an_error(tmp_path):
    cols = _columns(n=50)
    cols["t"] = cols["t"].copy()
    cols["t"][25:] += 0.1
    path = tmp_path / "f.csv"
    write_log(path, cols, META)
    with pytest.warns(LogWarning), pytest.raises(InputError) as exc:
        read_log(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: column t, lines ") and "no segment has 31 samples" in msg
    with pytest.warns(LogWarning, match="gap"):
        assert len(read_log(path, min_samples=20)) == 2


# ---------------------------------------------------------------------------
# arrays, describe


def test_log_from_arrays_matches_file_round_trip(tmp_path):
    cols = _full_columns(n=50)
    lg = log_from_arrays(
        cols["t"],
        np.stack([cols[c] for c in "xyz"], 1),
        np.stack([cols[c] for c in ("qw", "qx", "qy", "qz")], 1),
        np.stack([cols[f"T{j}"] for j in range(1, 5)], 1),
        {"alpha_c_deg": 12.5, "gamma_c_deg": 0, "vehicle": "ref"},
        omega_B=np.stack([cols[c] for c in "pqr"], 1),
        tension=cols["tension"],
        extra={"rssi": cols["zz_mode"]},
    )
    assert isinstance(lg, FlightLog)
    assert lg.meta == {
        "schema": SCHEMA,
        "alpha_c_deg": "12.5",
        "gamma_c_deg": "0",
        "vehicle": "ref",
    }
    assert lg.alpha_c == pytest.approx(math.radians(12.5))
    assert set(lg.optional) == {"omega_B", "tension"} and set(lg.extra) == {"rssi"}
    assert not lg.t.flags.writeable
    for ext in (".csv", ".h5"):
        path = tmp_path / f"sim{ext}"
        write_log(path, lg)
        (back,) = read_log(path)
        assert back.meta == lg.meta
        for name, a in lg.columns().items():
            assert np.array_equal(back.columns()[name], a), name
    assert "12.5" in describe(lg) and "50 samples" in describe(lg)
    assert "segment 1 of 1" in describe(lg)


def test_log_from_arrays_checks():
    cols = _columns(n=40)
    p = np.stack([cols[c] for c in "xyz"], 1)
    q = np.stack([cols[c] for c in ("qw", "qx", "qy", "qz")], 1)
    T = np.stack([cols[f"T{j}"] for j in range(1, 5)], 1)
    meta = {"alpha_c_deg": 0, "gamma_c_deg": 0}
    bad = q.copy()
    bad[7] *= 1.5
    with pytest.raises(InputError, match=r"^<arrays>: column qw .*sample 8: quaternion norm"):
        log_from_arrays(cols["t"], p, bad, T, meta)
    with pytest.raises(InputError, match="metadata alpha_c_deg: missing"):
        log_from_arrays(cols["t"], p, q, T, {"gamma_c_deg": 0})
    with pytest.raises(ValueError, match="T_cmd has shape"):
        log_from_arrays(cols["t"], p, q, T[:, :3], meta)
    with pytest.raises(TypeError, match="unknown optional array"):
        log_from_arrays(cols["t"], p, q, T, meta, gyro=p)


def test_describe_single_segment():
    (lg,) = read_log(DATA / "example.csv")
    text = describe(lg)
    assert text == ("tilt20-v8: 0.195 s, 200.0 Hz, 40 samples, segment 1 of 1, 0 gaps, tilt 20 deg")


# ---------------------------------------------------------------------------
# number syntax, plausible values, the declared circle plane


@pytest.mark.parametrize(
    ("column", "cell"),
    [("T2", "1_0"), ("x", "1_600.0"), ("t", "0.4_5"), ("aa_debug", "1_0"), ("y", "\u0661")],
    ids=["underscore-thrust", "underscore-x", "underscore-t", "underscore-unknown", "arabic-1"],
)
def test_csv_digit_separators_and_non_ascii_refused(tmp_path, column, cell):
    """float() accepts 1_0 (= 10) and non-ASCII digits; the log reader does not."""
    cols = _full_columns(n=40) if column == "aa_debug" else _columns(n=40)
    lines = _csv_text(cols)
    header = lines[N_META].split(",")
    cells = lines[_data_line(ROW) - 1].split(",")
    cells[header.index(column)] = cell
    lines[_data_line(ROW) - 1] = ",".join(cells)
    path = _write_lines(tmp_path / "sep.csv", lines)
    with pytest.raises(InputError) as exc:
        read_log(path)
    assert exc.value.source == str(path)
    assert exc.value.where == f"column {column}, line {_data_line(ROW)}", str(exc.value)
    assert f"not a number: {cell!r}" in exc.value.message


@pytest.mark.parametrize(
    ("column", "value", "words"),
    [
        ("x", 1e308, "m is not plausible (|x| <= 1000 m)"),
        ("z", -2e3, "m is not plausible (|z| <= 1000 m)"),
        ("T1", 1e308, "N is not plausible (|T1| <= 1000 N)"),
        ("t", 1e300, "s is not plausible (|t| <= 1e+10 s)"),
        ("tension", np.inf, "N is not plausible (|tension| <= 10000 N)"),
        ("p", -1e5, "rad/s is not plausible (|p| <= 1000 rad/s)"),
        ("xi_dot_ref", 5e3, "rad/s is not plausible"),
        ("vbat", 12600.0, "V is not plausible (|vbat| <= 1000 V)"),  # millivolts
        ("vbat", np.inf, "V is not plausible (|vbat| <= 1000 V)"),
        ("vbat", 0.0, "V is not plausible (0 < vbat <= 1000 V)"),  # PX4: unknown
        ("vbat", -11.1, "V is not plausible (0 < vbat <= 1000 V)"),
    ],
)
@pytest.mark.parametrize("ext", [".csv", ".h5"])
def test_implausible_values_refused(tmp_path, column, value, words, ext):
    cols = {k: np.array(v) for k, v in _full_columns(n=40).items()}
    cols[column][ROW] = value
    path = tmp_path / f"absurd{ext}"
    write_log(path, cols, META)
    with pytest.raises(InputError) as exc:
        read_log(path)
    row = f"line {_data_line(ROW)}" if ext == ".csv" else f"sample {ROW + 1}"
    assert exc.value.source == str(path)
    assert exc.value.where == f"column {column}, {row}", str(exc.value)
    assert words in exc.value.message, exc.value.message


def test_unknown_columns_are_not_bounded(tmp_path):
    cols = _columns(n=40)
    cols["raw_counts"] = np.full(40, 1e300)
    path = tmp_path / "u.csv"
    write_log(path, cols, META)
    (lg,) = read_log(path)
    assert lg.extra["raw_counts"][0] == 1e300


def _plane_columns(alpha_deg, gamma_deg=0.0, n=200, arc=3.0, noise=1e-3, seed=4):
    """A great circle (radius 1.6 m) in the plane R_IC = Rz(gamma) Rx(alpha), ``arc`` rad."""
    cols = _columns(n=n, seed=seed)
    rng = np.random.default_rng(seed)
    xi = np.linspace(0.3, 0.3 + arc, n)
    a, g = math.radians(alpha_deg), math.radians(gamma_deg)
    Rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    Rz = np.array([[math.cos(g), -math.sin(g), 0], [math.sin(g), math.cos(g), 0], [0, 0, 1]])
    p = 1.6 * np.stack([np.cos(xi), np.sin(xi), 0 * xi], 1) @ (Rz @ Rx).T
    p += rng.normal(0, noise, p.shape)
    cols.update(zip("xyz", p.T, strict=True))
    cols.update(zip(("qw", "qx", "qy", "qz"), _attitude(Rz @ Rx, xi, rng).T, strict=True))
    return cols


@pytest.mark.parametrize("ext", [".csv", ".h5"])
def test_declared_tilt_must_match_the_flown_plane(tmp_path, ext):
    """A 0 deg flight declared as 40 deg (it flipped the diagnosis): refused, naming the key."""
    path = tmp_path / f"lie{ext}"
    write_log(path, _plane_columns(0.0), {**META, "alpha_c_deg": "40"})
    with pytest.raises(InputError) as exc:
        read_log(path)
    assert exc.value.source == str(path) and exc.value.where == "metadata alpha_c_deg"
    assert "alpha_c_deg = 40" in exc.value.message and "tilt 0.0 deg" in exc.value.message
    assert "40.0 deg apart, more than 10" in exc.value.message


@pytest.mark.parametrize(("alpha", "gamma"), [(0, 0), (20, 0), (40, 0), (30, 120), (10, -45)])
def test_declared_plane_accepted(tmp_path, alpha, gamma):
    path = tmp_path / "ok.csv"
    write_log(path, _plane_columns(alpha, gamma), {**META, "alpha_c_deg": alpha,
                                                   "gamma_c_deg": gamma})
    (lg,) = read_log(path)
    assert lg.alpha_c == pytest.approx(math.radians(alpha))


def test_declared_heading_must_match_the_flown_plane(tmp_path):
    """Same tilt, other heading: the plane is still wrong; gamma_c_deg is named."""
    path = tmp_path / "heading.csv"
    write_log(path, _plane_columns(30.0, 90.0), {**META, "alpha_c_deg": "30"})
    with pytest.raises(InputError) as exc:
        read_log(path)
    assert exc.value.where == "metadata gamma_c_deg", str(exc.value)
    assert "gamma_c 90.0 deg" in exc.value.message


@pytest.mark.parametrize(
    "cols",
    [
        pytest.param(lambda: _plane_columns(0.0, arc=0.3), id="short-arc"),
        pytest.param(lambda: _plane_columns(0.0, noise=0.5), id="not-planar"),
    ],
)
def test_plane_not_checked_without_a_circle(tmp_path, cols):
    """Too little arc or no plane: nothing to compare the declaration with."""
    path = tmp_path / "free.csv"
    write_log(path, cols(), {**META, "alpha_c_deg": "40"})
    (lg,) = read_log(path)
    assert lg.alpha_c == pytest.approx(math.radians(40))


def test_example_flights_still_load():
    root = Path(__file__).parents[2] / "examples" / "flights"
    files = sorted(root.glob("*.csv"))
    assert len(files) == 7
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)
        for f in files:
            assert read_log(f)
