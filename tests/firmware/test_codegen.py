"""C header generation (gainsched.firmware.header, .cformat, .cfiles; the host builds of
.host) and the export-c / check commands."""

from __future__ import annotations

import dataclasses
import re
import shutil
import stat
import subprocess
import zlib

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text
from gainsched.firmware import runtime
from gainsched.firmware.cfiles import write_c_outputs, write_header
from gainsched.firmware.cformat import c_decimal, c_float, c_floats
from gainsched.firmware.header import render_header
from gainsched.firmware.host.compiler import STRICT_CFLAGS
from gainsched.firmware.host.lookup import build_host
from gainsched.firmware.host.size import code_bytes, flash_summary
from gainsched.firmware.runtime import MASK_NO_GAINS, c_identifier, runtime_data
from gainsched.model.reduced import Model
from gainsched.schedule.linearize import lqr_state_names
from gainsched.schedule.tables import load_table

from support import CC, PAPER_H5, synthetic_table


@pytest.fixture(scope="module")
def paper_header(paper_table):
    return render_header(runtime_data(paper_table))


def _array(text: str, name: str) -> np.ndarray:
    """The values of the C array ``name`` in a header, as float64 (hex float literals)."""
    body = text.split(f" {name}[", 1)[1].split("= {", 1)[1].split("};", 1)[0]
    toks = re.findall(r"-?0x[0-9a-f.]+p[+-]\d+f|-?0\.0f|\d+u", body)
    return np.array([float.fromhex(t[:-1]) if "x" in t else float(t[:-1]) for t in toks])


def test_c_float_is_exact():
    rng = np.random.default_rng(0)
    vals = np.r_[
        rng.normal(size=2000) * 10.0 ** rng.integers(-30, 30, 2000),
        [0.0, -0.0, 1.0, -1.0, 2.0**-149, 2.0**-126, 3.4e38, np.pi, 1 / 3],
    ].astype(np.float32)
    for v in vals:
        lit = c_float(v)
        assert lit.endswith("f")
        back = np.float32(float.fromhex(lit[:-1]) if "x" in lit else float(lit[:-1]))
        assert back == v and np.signbit(back) == np.signbit(v), (v, lit)
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError):
            c_float(bad)
    assert c_float(1.5) == "0x1.8p+0f" and c_decimal(1.6) == "1.6f"


def test_the_vectorised_literals_are_float_hex_text():
    """Issue 39: ``c_floats`` (the header's values, from the float32 bits) writes the text
    of ``c_float`` (``float.hex``) for every value: normal, zero of either sign,
    subnormal, extreme, every mantissa length; and refuses what it refuses."""
    rng = np.random.default_rng(1)
    vals = np.r_[
        rng.normal(size=5000) * 10.0 ** rng.integers(-40, 38, 5000),
        np.zeros(50), -np.zeros(3), 2.0 ** np.arange(-149, 128),
        [1e-40, -1e-45, 3.4028235e38, np.pi, 1 / 3, 1.5, 1.0009765625],
    ].astype(np.float32)
    assert c_floats(vals) == [c_float(v) for v in vals]
    assert c_floats(vals[:21].reshape(3, 7)) == [c_float(v) for v in vals[:21]]
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError):
            c_floats(np.array([1.0, bad]))


def test_c_identifier():
    assert c_identifier("paper") == "paper"
    assert c_identifier("Paper-v2.1") == "paper_v2_1"
    assert c_identifier("2fast") == "t2fast"
    assert c_identifier("--") == "table"


def test_header_is_deterministic(paper_table, tmp_path):
    a = render_header(runtime_data(paper_table))
    b = render_header(runtime_data(load_table(PAPER_H5)))
    assert a == b
    p1 = write_header(paper_table, tmp_path / "one")
    p2 = write_header(paper_table, tmp_path / "two")
    assert p1.read_bytes() == p2.read_bytes() == a.encode()
    assert p1.name == "paper_gains.h"
    assert stat.S_IMODE(p1.stat().st_mode) & 0o044  # readable by others, not 0600


def test_header_contents(paper_table, paper_header):
    d = runtime_data(paper_table)
    h = paper_header
    assert "${" not in h
    assert f'#define PAPER_CONFIG_SHA256 "{paper_table.config_sha256}"' in h
    assert f"#define PAPER_CRC32 0x{d.crc32():08x}u" in h
    for macro, val in zip(("N_TILT", "N_SPEED", "N_XI", "N_STATE"), d.dims, strict=True):
        assert f"#define PAPER_{macro} {val}u" in h
    assert not re.search(r"\b(nan|inf|infinity|huge_val)f?\b", h, re.I)
    assert "double" not in h and "malloc" not in h
    # every symbol defined by the header carries the table prefix
    defined = re.findall(r"^#define (\w+)", h, re.M) + re.findall(
        r"^static (?:inline )?(?:const )?\w+ \**(\w+)", h, re.M
    )
    assert defined and all(s.startswith(("PAPER_", "paper_")) for s in defined), defined
    # the data round-trip exactly through the literals
    for name, arr in (("paper_K_tilt0", d.K_tilt0), ("paper_xi_dot", d.xi_dot),
                      ("paper_u_d", d.u_d), ("paper_mask", d.mask)):
        np.testing.assert_array_equal(_array(h, name), arr.astype(np.float64).ravel())
    K = _array(h, "paper_K")
    np.testing.assert_array_equal(K, d.K.astype(np.float64).ravel())
    # every non-integer literal is a float literal (no double promotion)
    code = re.sub(r"/\*.*?\*/", "", h.split("#ifndef PAPER_GAINS_H")[1], flags=re.S)
    assert not re.search(r"\b\d+\.\d+\b(?!f)", code)


def test_infeasible_gains_are_zero_with_mask():
    t = synthetic_table()
    d = runtime_data(t)
    h = render_header(d)
    K = _array(h, "synth_K").reshape(t.K.shape)
    assert np.all(K[1, 3] == 0) and np.isnan(t.K[1, 3]).all()
    mask = _array(h, "synth_mask").reshape(t.reasons.shape).astype(int)
    assert np.all(mask[2, 3] & MASK_NO_GAINS) and np.all(mask[0, 4] & MASK_NO_GAINS)
    assert mask[1, 1, 2] == 2  # flagged, gains kept
    np.testing.assert_array_equal(mask & 0x7F, t.reasons)


def test_state_map_emitted_for_stateful_effects():
    d = runtime_data(synthetic_table(5, 7, 12, motor_lag=True, name="lag"))
    h = render_header(d)
    perm = _array(h, "lag_state_perm").astype(int)
    np.testing.assert_array_equal(perm, list(range(11)) + [14, 13, 12, 11])
    sign = _array(h, "lag_state_sign")
    np.testing.assert_array_equal(sign[:11], [1, -1, 1, -1, -1, 1, -1, -1, 1, -1, 1])
    assert "#define LAG_N_STATE 15u" in h


def test_crc_covers_documented_bytes(paper_table):
    d = runtime_data(paper_table)
    chunks = dict(d.crc_chunks())
    assert list(chunks) == ["dims", "xi_scale", "xi", "speed", "xi_dot", "tilt", "K_tilt0",
                            "K", "u_d", "phi_d", "state_sign", "state_perm", "mask", "vehicle",
                            "offset_harmonics", "offsets"]  # the paper table has offsets
    assert zlib.crc32(b"".join(chunks.values())) == d.crc32()
    assert d.nbytes() == sum(len(v) for k, v in chunks.items()
                             if k not in runtime.DESCRIPTOR_CHUNKS)


def test_write_c_outputs(tmp_path):
    table = tmp_path / "tables" / "paper.h5"
    table.parent.mkdir()
    shutil.copy(PAPER_H5, table)
    paths = write_c_outputs(table)
    assert [p.name for p in paths] == [
        "paper_gains.h",
        "paper_control.h",
        "gainsched_runtime.h",
        "gainsched_runtime.c",
        "gainsched_trig.h",
        "gainsched_control.h",
        "gainsched_control.c",
    ]
    assert all(p.parent == table.parent and p.stat().st_size > 0 for p in paths)
    again = write_c_outputs(table, tmp_path / "out")
    assert [p.read_bytes() for p in again] == [p.read_bytes() for p in paths]


@pytest.mark.needs_cc
def test_generated_header_compiles_and_corruption_fails_verify(tmp_path):
    """A header whose data were changed after generation (one literal: what flash
    corruption looks like) builds fine but fails <name>_verify."""
    d = runtime_data(synthetic_table())
    exe = build_host(d, tmp_path / "good", shared=False)
    res = subprocess.run([str(exe), "verify"], capture_output=True, text=True)
    assert res.returncode == 0 and f"crc 0x{d.crc32():08x}" in res.stdout
    bad_dir = tmp_path / "bad"
    build_host(d, bad_dir, shared=False)
    header = bad_dir / "synth_gains.h"
    text = header.read_text()
    head, body = text.split("synth_K[SYNTH_N_TILT_K]", 1)
    lit = re.search(r"-?0x[0-9a-f.]+p[+-]\d+f", body).group(0)
    value = np.float32(float.fromhex(lit[:-1]))
    tampered = c_float(np.nextafter(value, np.float32(np.inf)))
    header.write_text(head + "synth_K[SYNTH_N_TILT_K]" + body.replace(lit, tampered, 1))
    out = bad_dir / "synth_batch_bad"
    subprocess.run(
        [CC, *STRICT_CFLAGS, "-O1", "-DGS_BATCH_MAIN", f"-I{bad_dir}",
         str(bad_dir / "synth_batch.c"), str(bad_dir / "gainsched_runtime.c"), "-o", str(out)],
        check=True,
    )
    res = subprocess.run([str(out), "verify"], capture_output=True, text=True)
    assert res.returncode == 1 and "verify 64" in res.stdout  # GS_BAD_TABLE


def test_flash_summary(paper_table):
    lines = flash_summary(paper_table, compile_code=CC is not None)
    d = runtime_data(paper_table)
    assert f"{d.nbytes()} bytes" in lines[0]
    if CC is not None:
        size = code_bytes(cross=False)
        assert size is not None and 500 < size.nbytes < 20000
        assert "runtime code" in lines[1]


# --------------------------------------------------------------------------- CLI


def test_cli_export_c(tmp_path):
    table = tmp_path / "paper.h5"
    shutil.copy(PAPER_H5, table)
    res = CliRunner().invoke(cli, ["export-c", str(table), "-o", str(tmp_path / "c")])
    assert res.exit_code == 0, res.output
    assert "wrote" in res.output and "paper_gains.h" in res.output
    assert "flash: table data" in res.output
    assert (tmp_path / "c" / "gainsched_runtime.c").exists()
    res = CliRunner().invoke(cli, ["export-c", str(table), "--no-code-size"])
    assert res.exit_code == 0 and (tmp_path / "paper_gains.h").exists()


def test_cli_export_c_bad_table(tmp_path):
    bad = tmp_path / "nope.h5"
    bad.write_bytes(b"not hdf5")
    res = CliRunner().invoke(cli, ["export-c", str(bad)])
    assert res.exit_code == 2
    assert res.output.strip().count("\n") == 0 and "gainsched: error:" in res.output


@pytest.mark.slow
def test_cli_check_sample():
    res = CliRunner().invoke(
        cli, ["check", str(PAPER_H5), "--speed-stride", "7", "--max-error", "10"]
    )
    assert res.exit_code == 0, res.output
    assert "relative gain error" in res.output and "median" in res.output
    assert "worst spectral radius" in res.output and "PASS" in res.output
    strict = CliRunner().invoke(
        cli, ["check", str(PAPER_H5), "--speed-stride", "7", "--max-error", "0.01"]
    )
    assert strict.exit_code == 1 and "FAIL" in strict.output


def _midpoints(err, rho=0.97, u_rel=0.0):
    from gainsched.firmware.host.check import MidpointCheck, MidpointCircle

    n = len(err)
    return MidpointCheck(np.zeros(n), np.zeros(n), np.zeros(n), np.asarray(err, float),
                         np.zeros(n), [MidpointCircle(5.0, 0.0, rho, 0.96)], 0, np.full(n, u_rel),
                         np.zeros(n))


@pytest.mark.parametrize("res, max_error, nominal, passed", [
    (_midpoints([0.01, np.nan]), 0.02, False, True),
    (_midpoints([0.03]), 0.02, False, False),                 # a gain error above the bound
    (_midpoints([0.01], rho=1.01), 0.02, False, False),       # an unstable midpoint circle
    (_midpoints([np.nan]), 0.02, False, False),               # nothing checked
    (_midpoints([0.01], u_rel=0.05), 0.02, False, True),      # thrust error: not promised
    (_midpoints([0.01], u_rel=0.05), 0.02, True, False),      # a chosen grid promised it
], ids=["pass", "gain-error", "unstable", "nothing-checked", "lists-grid", "chosen-grid"])
def test_the_pass_rule_of_check(res, max_error, nominal, passed):
    """Issue 40: `gainsched check`'s pass rule is MidpointCheck.passed, one case each."""
    assert res.passed(max_error, nominal) is passed


def test_header_names_the_state_columns_and_integrals(paper_header):
    """Macros say where each state sits in K and x and which integral states exist."""
    assert "#define PAPER_X_XI 1u" in paper_header
    assert "#define PAPER_X_INT_DELTA 10u" in paper_header
    assert "#define PAPER_HAS_INT_DELTA 1" in paper_header
    assert "#define PAPER_HAS_INT_XI 0" in paper_header
    t = synthetic_table(3, 4, 8, motor_lag=True, azimuth_integral=True, seed=4, name="hold")
    t = dataclasses.replace(t, attrs={**t.attrs, "state_names": ",".join(
        lqr_state_names(Model(config_from_text(t.config_text))))})
    h = render_header(runtime_data(t))
    assert "#define HOLD_X_INT_DELTA 10u" in h and "#define HOLD_X_INT_XI 11u" in h
    assert "#define HOLD_HAS_INT_XI 1" in h and "#define HOLD_X_MOTOR_LAG_0 12u" in h
    sign = _array(h, "hold_state_sign")
    np.testing.assert_array_equal(sign[10:12], [1, -1])  # int_xi flips like xi
