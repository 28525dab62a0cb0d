"""Property-based checks of the front door (issue 12): mutated configs, logs and tables.

Hypothesis mutates valid inputs (a value replaced by an odd literal, a line
deleted or duplicated, a cell of a flight log replaced, a byte of a table
flipped) and every command must keep the contract: exit code 0 or 2, with 2
one line naming the file, never a traceback, and the old outputs intact. A
table that still loads after a flipped byte must hold exactly the old data
(the checksums leave no silent change).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gainsched.cli import cli
from gainsched.errors import InputError
from gainsched.schedule.tables import load_table

from support import PAPER_TOML as PAPER
from support import REPO, small_config_text

FLIGHT = REPO / "examples" / "flights" / "v9.csv"
SETTINGS = dict(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


CONFIG = small_config_text(name="prop")
LINES = CONFIG.splitlines()
VALUE_LINES = [i for i, ln in enumerate(LINES) if re.match(r"^\s*[A-Za-z_]+\s*=", ln)]

LITERALS = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "1e308", "-1e308", "1e-300", "0", "-1", "0.0",
                     "99999999999999999999", "true", '""', '"../../escape"', '"a/b"',
                     '"\\u0000"', '"x"', "[]", "[1, 2]", "[0, 0, 0, 0]", "[[1, 2], [3]]",
                     "{a = 1}", "1979-05-27", "[1e300, 2e300]", "[6, 6.0000001]",
                     "[2, 1e300]", "1000000", "1e9", "1e-6"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr).map(
        lambda s: {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(s, s)),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.lists(st.floats(-1e6, 1e6, allow_nan=False), max_size=14).map(
        lambda xs: "[" + ", ".join(repr(x) for x in xs) + "]"),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs"]),
            max_size=12).map(lambda s: '"' + s.replace("\\", "\\\\").replace('"', '\\"')
                                        .replace("\n", "\\n") + '"'),
)


@st.composite
def mutated_config(draw) -> bytes:
    lines = list(LINES)
    kind = draw(st.sampled_from(["value", "value", "value", "delete", "duplicate", "unknown",
                                 "garbage", "encoding"]))
    i = draw(st.sampled_from(VALUE_LINES))
    key = lines[i].split("=", 1)[0]
    if kind == "value":
        lines[i] = f"{key}= {draw(LITERALS)}"
    elif kind == "delete":
        del lines[i]
    elif kind == "duplicate":
        lines.insert(i, lines[i])
    elif kind == "unknown":
        lines.insert(i + 1, f"{draw(st.from_regex(r'[a-z_]{1,8}', fullmatch=True))} = 1")
    elif kind == "garbage":
        lines[i] = draw(st.text(max_size=30))
    text = "\n".join(lines) + "\n"
    if kind == "encoding":
        return text.replace("mass", "mäss", 1).encode(draw(st.sampled_from(["latin-1",
                                                                            "utf-16"])))
    return text.encode("utf-8", errors="surrogatepass")


def assert_contract(res, source):
    assert res.exit_code in (0, 2), (res.exit_code, res.output)
    assert "Traceback" not in res.output
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gainsched: error: "), res.stderr
        assert str(source) in lines[0] or "command line" in lines[0], lines[0]


@settings(max_examples=120, **SETTINGS)
@given(data=mutated_config())
def test_mutated_config_validate(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("cfg") / "prop.toml"
    path.write_bytes(data)
    assert_contract(CliRunner().invoke(cli, ["validate", str(path)]), path)


@pytest.mark.slow
@settings(max_examples=25, **SETTINGS)
@given(data=mutated_config())
def test_mutated_config_build_keeps_old_outputs(tmp_path_factory, data):
    """A config that passes validate builds; one that fails leaves the old set untouched."""
    d = tmp_path_factory.mktemp("build")
    out = d / "out"
    out.mkdir()
    old = {"prop.h5": b"old table", "prop_gains.h": b"old header"}
    for name, blob in old.items():
        (out / name).write_bytes(blob)
    path = d / "prop.toml"
    path.write_bytes(data)
    res = CliRunner().invoke(cli, ["build", str(path), "-o", str(out), "-j", "1"])
    assert_contract(res, path)
    if res.exit_code == 2:
        assert {p.name: p.read_bytes() for p in out.iterdir()} == old


LOG_LINES = FLIGHT.read_text().splitlines()
HEADER_AT = next(i for i, ln in enumerate(LOG_LINES) if not ln.startswith("#"))
SHORT_LOG = LOG_LINES[: HEADER_AT + 1 + 200]  # one second at 200 Hz: fast to compare
CELLS = st.one_of(
    st.sampled_from(["", "nan", "inf", "-inf", "1e308", "-1e308", "1_0", "0x10", "1e", "--1",
                     "NaN", " 1", "1,5", "abc", "0"]),
    st.floats().map(repr),
    st.text(max_size=8),
)


@st.composite
def mutated_log(draw) -> str:
    lines = list(SHORT_LOG)
    kind = draw(st.sampled_from(["cell", "cell", "cell", "meta", "drop-row", "drop-column"]))
    if kind == "cell":
        r = draw(st.integers(HEADER_AT + 1, len(lines) - 1))
        cells = lines[r].split(",")
        cells[draw(st.integers(0, len(cells) - 1))] = draw(CELLS).replace(",", ";")
        lines[r] = ",".join(cells)
    elif kind == "meta":
        m = draw(st.integers(0, HEADER_AT - 1))
        key = lines[m].split(":", 1)[0]
        lines[m] = f"{key}: {draw(CELLS)}"
    elif kind == "drop-row":
        del lines[draw(st.integers(HEADER_AT + 1, len(lines) - 1))]
    else:
        c = draw(st.integers(0, len(lines[HEADER_AT].split(",")) - 1))
        lines[HEADER_AT:] = [",".join(x for j, x in enumerate(ln.split(",")) if j != c)
                             for ln in lines[HEADER_AT:]]
    return "\n".join(lines) + "\n"


@settings(max_examples=60, **SETTINGS)
@given(text=mutated_log())
def test_mutated_log_compare(tmp_path_factory, text):
    d = tmp_path_factory.mktemp("log")
    log = d / "flight.csv"
    log.write_text(text)
    res = CliRunner().invoke(cli, ["compare", str(PAPER), str(log), "--no-paper"])
    assert_contract(res, log)


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    d = tmp_path_factory.mktemp("table")
    (d / "prop.toml").write_text(CONFIG)
    res = CliRunner().invoke(cli, ["build", str(d / "prop.toml"), "-o", str(d)])
    assert res.exit_code == 0, res.output
    return d / "prop.h5"


@pytest.mark.slow
@settings(max_examples=80, **SETTINGS)
@given(pos=st.floats(0, 1, exclude_max=True), bit=st.integers(0, 7))
def test_flipped_table_bit_is_refused_or_harmless(small_table, tmp_path_factory, pos, bit):
    """A flipped bit anywhere in the file: refused with one line, or (padding, unused
    metadata) the table loads with exactly the original data."""
    blob = bytearray(small_table.read_bytes())
    i = int(pos * len(blob))
    blob[i] ^= 1 << bit
    bad = tmp_path_factory.mktemp("flip") / "prop.h5"
    bad.write_bytes(bytes(blob))
    res = CliRunner().invoke(cli, ["inspect", str(bad)])
    assert_contract(res, bad)
    if res.exit_code == 0:
        a, b = load_table(small_table), load_table(bad)
        for name in ("K_tilt0", "K", "u_d", "phi_d", "tension", "reasons", "spectral_radius"):
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    else:
        with pytest.raises(InputError):
            load_table(bad)
