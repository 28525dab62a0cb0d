"""Config validation: every rule rejects a bad file naming the file and the dotted key.

Each bad config is the paper config with exactly one thing changed (one line
replaced, one key removed or one key/table added), so a test can only pass
because of the rule it is about.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text, load_config
from gainsched.errors import InputError

# --------------------------------------------------------------------------- text editing


def _section_span(lines: list[str], section: str) -> tuple[int, int]:
    """Line range [start, end) of the body of ``[section]`` ("" = the top level)."""
    headers = [i for i, ln in enumerate(lines) if re.match(r"\s*\[", ln)]
    if section == "":
        return 0, headers[0]
    start = next(i for i in headers if lines[i].split("#")[0].strip() == f"[{section}]") + 1
    end = next((i for i in headers if i >= start), len(lines))
    return start, end


def _key_line(lines: list[str], section: str, key: str) -> int:
    start, end = _section_span(lines, section)
    hits = [i for i in range(start, end) if re.match(rf"\s*{re.escape(key)}\s*=", lines[i])]
    assert len(hits) == 1, f"{section}.{key} not found exactly once"
    return hits[0]


def set_key(text: str, section: str, key: str, value: str) -> str:
    """Replace the line of an existing ``key`` in ``[section]`` by ``key = value``."""
    lines = text.splitlines()
    lines[_key_line(lines, section, key)] = f"{key} = {value}"
    return "\n".join(lines) + "\n"


def drop_key(text: str, section: str, key: str) -> str:
    """Remove the line of ``key`` from ``[section]``."""
    lines = text.splitlines()
    del lines[_key_line(lines, section, key)]
    return "\n".join(lines) + "\n"


def add_key(text: str, section: str, key: str, value: str) -> str:
    """Insert ``key = value`` as the first line of ``[section]`` (must not exist yet)."""
    lines = text.splitlines()
    start, end = _section_span(lines, section)
    assert not any(re.match(rf"\s*{re.escape(key)}\s*=", ln) for ln in lines[start:end])
    lines.insert(start, f"{key} = {value}")
    return "\n".join(lines) + "\n"


def append(text: str, extra: str) -> str:
    """Append raw TOML (e.g. a new table) at the end."""
    return text.rstrip("\n") + "\n" + extra + "\n"


def _q_matrix_not_psd() -> str:
    """An 11x11 symmetric Q with eigenvalues 1 +- 2 in the (0, 1) block: one is negative."""
    Q = np.eye(11)
    Q[0, 1] = Q[1, 0] = 2.0
    return "[" + ", ".join("[" + ", ".join(f"{x:g}" for x in row) + "]" for row in Q) + "]"


NON_SYMMETRIC_J = "[[2.5e-3, 1e-5, 0], [0, 2.5e-3, 0], [0, 0, 4.5e-3]]"

# (id, edit function of the paper text, dotted key the error must name)
BAD = [
    ("unknown-top", lambda t: add_key(t, "", "colour", '"red"'), "colour"),
    ("unknown-section", lambda t: add_key(t, "vehicle", "wingspan", "1.0"), "vehicle.wingspan"),
    ("unknown-effect-key", lambda t: add_key(t, "effects.drag", "mu3", "0.1"), "effects.drag.mu3"),
    ("unknown-effect", lambda t: append(t, "[effects.magic]\nk = 1.0"), "effects.magic"),
    ("string-mass", lambda t: set_key(t, "vehicle", "mass", '"heavy"'), "vehicle.mass"),
    ("bool-length", lambda t: set_key(t, "tether", "length", "true"), "tether.length"),
    ("list-kappa", lambda t: set_key(t, "vehicle", "kappa", "[0.016]"), "vehicle.kappa"),
    ("missing-mass", lambda t: drop_key(t, "vehicle", "mass"), "vehicle.mass"),
    ("misspelt-arm-length", lambda t: t.replace("arm_length =", "arm_lenght ="),
     "vehicle.arm_lenght"),
    ("misspelt-optional-key", lambda t: add_key(t, "control", "rate_hzz", "500"),
     "control.rate_hzz"),
    ("missing-length", lambda t: drop_key(t, "tether", "length"), "tether.length"),
    ("missing-Q", lambda t: drop_key(t, "control", "Q"), "control.Q"),
    ("missing-speeds", lambda t: drop_key(t, "grid", "speeds"), "grid.speeds"),
    ("zero-mass", lambda t: set_key(t, "vehicle", "mass", "0.0"), "vehicle.mass"),
    ("negative-mass", lambda t: set_key(t, "vehicle", "mass", "-0.5"), "vehicle.mass"),
    (
        "inertia-not-pd",
        lambda t: set_key(t, "vehicle", "inertia", "[1e-3, -1e-3, 1e-3]"),
        "vehicle.inertia",
    ),
    (
        "inertia-not-symmetric",
        lambda t: set_key(t, "vehicle", "inertia", NON_SYMMETRIC_J),
        "vehicle.inertia",
    ),
    (
        "thrust-min-eq-max",
        lambda t: set_key(t, "vehicle", "thrust_min", "3.5"),
        "vehicle.thrust_min",
    ),
    (
        "thrust-min-gt-max",
        lambda t: set_key(t, "vehicle", "thrust_min", "4.0"),
        "vehicle.thrust_min",
    ),
    (
        "offset-ge-length",
        lambda t: set_key(t, "tether", "attachment_offset", "1.5"),
        "tether.attachment_offset",
    ),
    ("Q-size", lambda t: set_key(t, "control", "Q", "[1, 1, 1]"), "control.Q"),
    ("Q-not-psd", lambda t: set_key(t, "control", "Q", _q_matrix_not_psd()), "control.Q"),
    ("R-not-pd", lambda t: set_key(t, "control", "R", "[1, 0, 1, 1]"), "control.R"),
    ("R-size", lambda t: set_key(t, "control", "R", "[1, 1, 1]"), "control.R"),
    ("speeds-empty", lambda t: set_key(t, "grid", "speeds", "[]"), "grid.speeds"),
    ("speeds-unsorted", lambda t: set_key(t, "grid", "speeds", "[2, 4, 3]"), "grid.speeds"),
    ("tilts-unsorted", lambda t: set_key(t, "grid", "tilts_deg", "[0, 20, 10]"), "grid.tilts_deg"),
    ("tilt-negative", lambda t: set_key(t, "grid", "tilts_deg", "[-10, 0, 10]"), "grid.tilts_deg"),
    ("tilt-90", lambda t: set_key(t, "grid", "tilts_deg", "[0, 45, 90]"), "grid.tilts_deg"),
    (
        "azimuth-odd",
        lambda t: set_key(t, "grid", "azimuth_samples", "35"),
        "grid.azimuth_samples",
    ),
    (
        "azimuth-float",
        lambda t: set_key(t, "grid", "azimuth_samples", "36.0"),
        "grid.azimuth_samples",
    ),
    (
        "azimuth-string",
        lambda t: set_key(t, "grid", "azimuth_samples", '"36"'),
        "grid.azimuth_samples",
    ),
    ("drag-mu1-negative", lambda t: set_key(t, "effects.drag", "mu1", "-1"), "effects.drag.mu1"),
    # name: a file stem and a C prefix
    ("name-escape", lambda t: set_key(t, "", "name", '"../../escape"'), "name"),
    ("name-subdir", lambda t: set_key(t, "", "name", '"sub/dir"'), "name"),
    ("name-empty", lambda t: set_key(t, "", "name", '""'), "name"),
    ("name-nul", lambda t: set_key(t, "", "name", '"a\\u0000b"'), "name"),
    ("name-hidden", lambda t: set_key(t, "", "name", '".paper"'), "name"),
    ("name-dash-first", lambda t: set_key(t, "", "name", '"-paper"'), "name"),
    ("name-space", lambda t: set_key(t, "", "name", '"my paper"'), "name"),
    ("name-non-ascii", lambda t: set_key(t, "", "name", '"papér"'), "name"),
    ("name-too-long", lambda t: set_key(t, "", "name", '"' + "a" * 65 + '"'), "name"),
    # grid axes as the float32 tables store them, and upper bounds
    ("speeds-f32", lambda t: set_key(t, "grid", "speeds", "[6, 6.0000001, 7, 8]"), "grid.speeds"),
    (
        "xi-dot-f32",
        lambda t: set_key(t, "grid", "speeds", "[2, 7.9000004, 7.900001]"),
        "grid.speeds",
    ),
    (
        "tilts-f32",
        lambda t: set_key(t, "grid", "tilts_deg", "[0, 10, 10.0000001]"),
        "grid.tilts_deg",
    ),
    ("speeds-overflow", lambda t: set_key(t, "grid", "speeds", "[2, 1e300]"), "grid.speeds"),
    ("speeds-above-100", lambda t: set_key(t, "grid", "speeds", "[2, 101]"), "grid.speeds"),
    (
        "xi-dot-above-limit",  # 15 m/s on a 1 cm tether (the offset must be < length, the
        # arms shorter than the tether)
        lambda t: set_key(set_key(set_key(t, "tether", "attachment_offset", "0"), "tether",
                                  "length", "0.01"), "vehicle", "arm_length", "0.005"),
        "grid.speeds",
    ),
    (
        "azimuth-above-4096",
        lambda t: set_key(t, "grid", "azimuth_samples", "4098"),
        "grid.azimuth_samples",
    ),
    # weights: the azimuth must be weighted (it is an exact integrator)
    ("Q-zero", lambda t: set_key(t, "control", "Q", "[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]"),
     "control.Q"),
    ("Q-xi-zero", lambda t: set_key(t, "control", "Q", "[3, 0, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5]"),
     "control.Q"),
    # physically absurd values
    ("mass-tiny", lambda t: set_key(t, "vehicle", "mass", "1e-300"), "vehicle.mass"),
    ("mass-huge", lambda t: set_key(t, "vehicle", "mass", "2000"), "vehicle.mass"),
    (
        "inertia-triangle",
        lambda t: set_key(t, "vehicle", "inertia", "[1e-3, 1e-3, 4.5e-3]"),
        "vehicle.inertia",
    ),
    ("rate-too-low", lambda t: set_key(t, "control", "rate_hz", "40"), "control.rate_hz"),
    ("rate-too-high", lambda t: set_key(t, "control", "rate_hz", "2e5"), "control.rate_hz"),
    ("rate-1GHz", lambda t: set_key(t, "control", "rate_hz", "1e9"), "control.rate_hz"),
    # [limits]
    ("limits-zero", lambda t: append(t, "[limits]\nmax_memory_gib = 0"), "limits.max_memory_gib"),
    ("limits-negative", lambda t: append(t, "[limits]\nmax_build_cpu_s = -1"),
     "limits.max_build_cpu_s"),
    ("limits-inf", lambda t: append(t, "[limits]\nmax_build_cpu_s = inf"),
     "limits.max_build_cpu_s"),
    ("limits-unknown", lambda t: append(t, "[limits]\nmax_disk_gib = 1"), "limits.max_disk_gib"),
]
BAD_BY_ID = {case[0]: case for case in BAD}

# representative subset also run through the CLI (one per kind of rule)
CLI_SUBSET = [
    "unknown-section",
    "unknown-effect",
    "string-mass",
    "missing-Q",
    "inertia-not-pd",
    "offset-ge-length",
    "R-not-pd",
    "speeds-unsorted",
    "azimuth-odd",
    "drag-mu1-negative",
]


def _run_validate(path):
    return CliRunner().invoke(cli, ["validate", str(path)])


def _assert_one_line_error(result, *needles):
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)
    err = result.stderr.strip().splitlines()
    assert len(err) == 1, result.stderr
    for needle in needles:
        assert needle in err[0], err[0]
    assert "Traceback" not in result.stderr + result.stdout


# --------------------------------------------------------------------------- tests


def test_paper_config_matches_design_section_8(paper_config):
    c = paper_config
    v, t = c.vehicle, c.tether
    assert v.mass == 0.5
    np.testing.assert_array_equal(v.inertia, np.diag([2.5e-3, 2.5e-3, 4.5e-3]))
    assert (v.layout, v.arm_length, v.kappa) == ("x", 0.17, 0.016)
    assert (v.thrust_min, v.thrust_max) == (0.1, 3.5)
    assert (t.length, t.attachment_offset, t.link) == (1.5, 0.1, "rigid")
    assert c.radius == pytest.approx(1.6, abs=1e-15)
    drag = {e.name: e.param_dict() for e in c.effects}
    assert drag == {"drag": {"mu1": 0.172, "mu2": 0.0025}}
    assert c.g == 9.81
    assert c.control.rate_hz == 1000.0 and c.control.dt == pytest.approx(1e-3, rel=1e-15)
    # eq. 24: state order delta, xi, delta', xi', phi, theta, chi, wx, wy, wz, int(delta)
    q_eq24 = [3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5]
    np.testing.assert_array_equal(c.control.Q, np.diag(q_eq24))
    np.testing.assert_array_equal(c.control.R, np.eye(4))
    # refined below 6 m/s and above 20 deg so midpoint interpolation stays below 2% (issue 4);
    # down to the tension margin at tilt 0 (issue 14); 37 deg for the attitude offsets' kink
    # (issue 15)
    speeds = [1.3, 2, 2.5, 3, 3.5, 4, 4.5, 5, 5.5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]
    np.testing.assert_array_equal(c.grid.speeds, speeds)
    np.testing.assert_allclose(
        c.grid.tilts, np.deg2rad([0, 10, 20, 28, 34, 37, 40]), rtol=0, atol=1e-15
    )
    assert c.grid.azimuth_samples == 36
    assert c.feasibility.attitude_offsets == "free"


def test_edit_helpers_change_one_line(paper_text):
    """The helpers change exactly one line (so each bad config differs in one thing)."""
    a = paper_text.splitlines()
    b = set_key(paper_text, "vehicle", "mass", "0.7").splitlines()
    assert len(a) == len(b) and sum(x != y for x, y in zip(a, b, strict=True)) == 1
    assert "mass = 0.7" in b
    assert len(drop_key(paper_text, "tether", "length").splitlines()) == len(a) - 1
    # unchanged round trip: replacing a line by itself keeps a loadable config
    config_from_text(set_key(paper_text, "vehicle", "mass", "0.5"), "good.toml")


@pytest.mark.parametrize(("case", "edit", "key"), BAD, ids=[c[0] for c in BAD])
def test_bad_config_names_file_and_key(paper_text, case, edit, key):
    text = edit(paper_text)
    assert text != paper_text
    with pytest.raises(InputError) as info:
        config_from_text(text, "bad.toml")
    msg = str(info.value)
    assert info.value.where == key, msg
    assert msg.startswith("bad.toml: "), msg
    assert key in msg, msg


def test_specific_messages(paper_text):
    """A few rules whose message should say which property is violated."""
    cases = [
        ("inertia-not-symmetric", "symmetric"),
        ("inertia-not-pd", "positive definite"),
        ("Q-not-psd", "semidefinite"),
        ("R-not-pd", "positive definite"),
        ("speeds-unsorted", "increasing"),
        ("tilt-90", "< 90"),
        ("unknown-effect", "unknown effect"),
        ("missing-mass", "missing"),
        ("misspelt-arm-length", "vehicle.arm_lenght: unknown key (did you mean arm_length?)"),
        ("misspelt-optional-key", "control.rate_hzz: unknown key (did you mean rate_hz?)"),
        ("drag-mu1-negative", "[0, 10]"),
        ("name-escape", "1-64 characters from A-Z a-z 0-9 _ - . starting with a letter"),
        ("name-escape", "'../../escape'"),
        ("speeds-f32", "equal in float32"),
        ("xi-dot-f32", "azimuth rates"),
        ("tilts-f32", "equal in float32"),
        ("speeds-overflow", "<= 100 m/s"),
        ("xi-dot-above-limit", "above the runtime's limit 1000 rad/s"),
        ("azimuth-above-4096", "[4, 4096]"),
        ("Q-zero", "all zero"),
        ("Q-xi-zero", "xi entry (index 1"),
        ("mass-tiny", "[0.01, 1000] kg"),
        ("inertia-triangle", "triangle inequality"),
        ("rate-too-low", "26 steps over the fastest circle"),
        ("rate-too-high", "<= 100000 Hz"),
    ]
    for case, words in cases:
        _, edit, _ = BAD_BY_ID[case]
        with pytest.raises(InputError, match=re.escape(words)):
            config_from_text(edit(paper_text), "bad.toml")


def test_invalid_toml_syntax(paper_text, tmp_path):
    lines = paper_text.splitlines()
    i = _key_line(lines, "vehicle", "mass")
    text = set_key(paper_text, "vehicle", "mass", "= 0.5")
    with pytest.raises(InputError) as info:
        config_from_text(text, "bad.toml")
    msg = str(info.value)
    assert msg.startswith("bad.toml: ") and "not valid TOML" in msg, msg
    assert f"line {i + 1}" in msg, msg  # the parser's position is passed through
    path = tmp_path / "bad.toml"
    path.write_text(text)
    _assert_one_line_error(_run_validate(path), str(path), "not valid TOML")


def test_nonexistent_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(InputError) as info:
        load_config(path)
    assert str(path) in str(info.value) and "cannot read" in str(info.value)
    _assert_one_line_error(_run_validate(path), str(path), "cannot read")


@pytest.mark.parametrize("case", CLI_SUBSET)
def test_cli_validate_bad_config(paper_text, tmp_path, case):
    _, edit, key = BAD_BY_ID[case]
    path = tmp_path / "bad.toml"
    path.write_text(edit(paper_text))
    _assert_one_line_error(_run_validate(path), str(path), key)


def test_cli_validate_good_config(paper_path):
    result = _run_validate(paper_path)
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith(f"{paper_path}: ok")
    assert result.stderr == ""


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [
        ("control", "R", '["1", "1", "1", "1"]'),
        ("vehicle", "inertia", "[[2.5e-3, false, 0], [false, 2.5e-3, 0], [0, 0, 4.5e-3]]"),
    ],
)
def test_list_entries_must_be_numbers(paper_text, section, key, value):
    with pytest.raises(InputError, match=re.escape(f"{section}.{key}")):
        config_from_text(set_key(paper_text, section, key, value), "bad.toml")


# --------------------------------------------------------------------------- encodings


@pytest.mark.parametrize(
    ("encode", "words"),
    [
        (lambda t: t.encode("utf-16"), "UTF-16 text (byte-order mark); save it as UTF-8"),
        (lambda t: t.encode("utf-16-be"), "looks like UTF-16 text"),
        (lambda t: t.encode("utf-16-le"), "looks like UTF-16 text"),
        (lambda t: t.encode("utf-32"), "UTF-32 text (byte-order mark); save it as UTF-8"),
        (lambda t: ("# caf\u00e9\n" + t).encode("latin-1"), "not UTF-8 text (byte 0xe9 at line 1"),
        (lambda t: t.encode() + b"\x00", "not a text file (NUL byte"),
    ],
    ids=["utf16-bom", "utf16-be", "utf16-le", "utf32-bom", "latin1", "nul"],
)
def test_non_utf8_config_is_named(paper_text, tmp_path, encode, words):
    path = tmp_path / "enc.toml"
    path.write_bytes(encode(paper_text))
    with pytest.raises(InputError) as info:
        load_config(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and words in msg and "\n" not in msg, msg
    _assert_one_line_error(_run_validate(path), str(path), words)


def test_utf8_bom_and_crlf_accepted(paper_text, paper_config, tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + paper_text.replace("\n", "\r\n").encode())
    cfg = load_config(path)
    assert cfg.name == "paper" and cfg.vehicle.mass == 0.5
    assert cfg.text == paper_config.text and cfg.sha256 == paper_config.sha256


# --------------------------------------------------------------------------- name


@pytest.mark.parametrize("name", ["paper-v2.1", "9lives", "A_b-C.d", "a" * 64])
def test_good_names(paper_text, name):
    assert config_from_text(set_key(paper_text, "", "name", f'"{name}"'), "x.toml").name == name


def test_default_name_from_file_stem(paper_text, tmp_path):
    text = drop_key(paper_text, "", "name")
    good = tmp_path / "vehicle-2.toml"
    good.write_text(text)
    assert load_config(good).name == "vehicle-2"
    bad = tmp_path / "my vehicle.toml"
    bad.write_text(text)
    with pytest.raises(InputError) as info:
        load_config(bad)
    assert info.value.where == "name" and info.value.source == str(bad)
    assert "default from the file name 'my vehicle'" in str(info.value)
    assert "set name = 'my_vehicle'" in str(info.value)
    _assert_one_line_error(_run_validate(bad), str(bad), "name", "set name")
    # in-memory sources are no file names: their stem stays the default, unchecked
    assert config_from_text(text).name == "<string>"


# --------------------------------------------------------------------------- physics


def test_plausible_edges_pass(paper_text):
    """The bounds leave real vehicles alone: a flat plate (J1 + J2 = J3), the mass and
    speed limits themselves, the lowest rate with 32 steps, and [limits] given."""
    ok = [
        set_key(paper_text, "vehicle", "inertia", "[1e-3, 3e-3, 4e-3]"),
        set_key(paper_text, "vehicle", "mass", "0.01"),
        set_key(paper_text, "control", "rate_hz", "48"),
        set_key(paper_text, "grid", "speeds", "[2, 6, 6.000001, 100]"),
        append(paper_text, "[limits]\nmax_memory_gib = 0.5\nmax_build_cpu_s = 60"),
    ]
    for text in ok:
        config_from_text(text, "ok.toml")
    cfg = config_from_text(append(paper_text, "[limits]\nmax_memory_gib = 0.5"), "ok.toml")
    assert (cfg.limits.max_memory_gib, cfg.limits.max_build_cpu_s) == (0.5, 1800.0)


def test_integral_states_set_the_size_of_Q(paper_config):
    """``integrator`` (int_delta) and ``azimuth_integral`` (int_xi) each add one LQR state
    after the reduced state; Q must have one entry per state, and a wrong size is refused
    naming the order."""
    base = paper_config
    assert base.control.integrators == ("int_delta",) and base.control.n_lqr == 11
    both = base.with_values({"control.azimuth_integral": True,
                             "control.Q": [3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5, 2.0]})
    assert both.control.integrators == ("int_delta", "int_xi") and both.control.n_lqr == 12
    none = base.with_values({"control.integrator": False,
                             "control.Q": [3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1]})
    assert none.control.integrators == () and none.control.n_lqr == 10
    with pytest.raises(InputError, match=r"control\.Q: must have 12 diagonal entries \(delta, "
                                         r"xi, .*, int_delta, int_xi\) or be 12x12, got 11"):
        base.with_values({"control.azimuth_integral": True})
    Q = np.diag([3, 0.2, 1, 1, 1, 2, 0.5, 1, 1, 1, 0.5, 2.0])
    Q[0, 11] = Q[11, 0] = 0.1  # int_xi flips under the direction mirror, delta does not
    with pytest.raises(InputError, match=r"control\.Q: must not couple .*int_xi"):
        base.with_values({"control.azimuth_integral": True, "control.Q": Q.tolist()})


def test_max_time_constant_is_optional_bounded_below_and_needs_a_periodic_terminal(
        paper_config):
    """``[control] max_time_constant_s``: None by default; at least 10 control periods
    (0.01 s at 1 kHz); positive; only with the periodic terminal cost (a one-period
    horizon guarantees no decay rate). Errors name the key."""
    base = paper_config
    assert base.control.max_time_constant_s is None
    assert base.with_values({"control.max_time_constant_s": 1.5}).control.max_time_constant_s \
        == 1.5
    assert base.with_values({"control.max_time_constant_s": 0.01}).control \
        .max_time_constant_s == 0.01
    with pytest.raises(InputError, match=r"control\.max_time_constant_s: must be at least 10 "
                                         r"control periods \(0\.01 s at 1000 Hz\), got 0\.005"):
        base.with_values({"control.max_time_constant_s": 0.005})
    with pytest.raises(InputError, match=r"control\.max_time_constant_s: .*positive|> 0"):
        base.with_values({"control.max_time_constant_s": -1.0})
    with pytest.raises(InputError, match=r"control\.max_time_constant_s: needs terminal = "
                                         r"\"periodic\""):
        base.with_values({"control.max_time_constant_s": 1.5, "control.terminal": "single-period"})


def test_max_gain_is_optional_and_positive(paper_config):
    base = paper_config
    assert base.control.max_gain is None
    assert base.with_values({"control.max_gain": 50.0}).control.max_gain == 50.0
    with pytest.raises(InputError, match=r"control\.max_gain: "):
        base.with_values({"control.max_gain": 0.0})


def test_margin_bounds_are_optional_positive_within_the_search_and_need_margins(paper_config):
    base = paper_config
    assert base.control.margins and base.control.min_delay_margin_ms is None
    c = base.with_values({"control.min_gain_margin_db": 6.0, "control.min_delay_margin_ms": 10})
    assert (c.control.min_gain_margin_db, c.control.min_delay_margin_ms) == (6.0, 10.0)
    for key, value, what in (("min_gain_margin_db", 0.0, "must be > 0"),
                             ("min_gain_margin_db", 21.0, "beyond the margins' search range "
                              "(20 dB"),
                             ("min_delay_margin_ms", 60.0, "beyond the margins' search range "
                              "(50 ms")):
        with pytest.raises(InputError, match=rf"control\.{key}: .*{re.escape(what)}"):
            base.with_values({f"control.{key}": value})
    with pytest.raises(InputError, match=r"control\.min_delay_margin_ms: needs margins = true"):
        base.with_values({"control.min_delay_margin_ms": 10.0, "control.margins": False})


def test_config_is_a_flat_namespace_over_private_modules():
    """gainsched.config re-exports its private modules (issue 40): every name in its
    ``__all__`` resolves, the classes and functions come from a private module of the
    package, and every name the package's modules, the tests and the examples import
    from ``gainsched.config`` is in ``__all__``."""
    import ast
    from pathlib import Path

    import gainsched.config as pkg

    assert len(pkg.__all__) == len(set(pkg.__all__))
    for name in pkg.__all__:
        obj = getattr(pkg, name)
        module = getattr(obj, "__module__", None)
        if callable(obj) and module and module.startswith("gainsched.config"):
            assert module.split(".")[-1].startswith("_"), (name, module)
    root = Path(__file__).parents[1]
    imported = set()
    for path in [*root.glob("gainsched/**/*.py"), *root.glob("tests/**/*.py"),
                 *root.glob("examples/**/*.py")]:
        if path.parent == root / "gainsched" / "config":
            continue  # the package's own modules
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (
                    node.module == "gainsched.config" or (node.level and node.module == "config")):
                imported |= {a.name for a in node.names}
    assert imported and imported <= set(pkg.__all__), sorted(imported - set(pkg.__all__))
