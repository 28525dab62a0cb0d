"""PX4 conventions out (issue 36): the controller's outputs in PX4's motor numbering and as
normalised commands through PX4's thrust curve (``[firmware] motor_order``, ``command``),
C against its Python reference, the curve against the default export's newtons, the
simulator flying the same, and the config's and the C runtime's checks of them."""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
import sys

import numpy as np
import pytest

from gainsched.actuators import (
    MOTOR_ORDERS,
    PX4_MOTOR_ORDER,
    command_from_thrust,
    slots_from_order,
    thrust_from_command,
)
from gainsched.errors import InputError
from gainsched.firmware.controller import CTRL_IDLE, Controller, controller_params
from gainsched.firmware.host.sil import CController
from gainsched.firmware.runtime import Interpolator, runtime_data
from gainsched.schedule.onboard import outputs_from_config
from gainsched.sim.loop import load_scenario, metrics, runtime_scheduler, simulate

from support import PAPER_H5, recorded_rows

PX4 = {"firmware.motor_order": "px4", "firmware.command": "normalized",
       "firmware.thr_mdl_fac": 0.3, "firmware.thrust_max_N": 4.0}


@pytest.fixture(scope="module")
def px4_config(paper_config):
    """The paper config with PX4 outputs: quad-X order, commands through THR_MDL_FAC 0.3
    with 4 N at full command (the motors' range is 0.1..3.5 N)."""
    return paper_config.with_values(PX4)


# ---------------------------------------------------------------- the thrust curve
@pytest.mark.parametrize("fac", [0.0, 0.3, 1.0])
def test_thrust_curve_inverse_is_the_quadratics_root(fac):
    """command_from_thrust is the root in 0..1 of f u^2 + (1 - f) u - T / T_full = 0
    (numpy's polynomial roots, an independent formulation) to 1e-12, and
    thrust_from_command undoes it to 1e-12 N."""
    full = 6.0
    T = np.linspace(0.0, full, 41)
    u = command_from_thrust(T, fac, full)
    for Ti, ui in zip(T, u, strict=True):
        roots = np.roots([fac, 1.0 - fac, -Ti / full]) if fac else np.array([Ti / full])
        root = roots[(roots.real >= -1e-12) & (roots.real <= 1 + 1e-12)].real
        assert abs(ui - root.min()) < 1e-12, (Ti, ui, roots)
    assert np.abs(thrust_from_command(u, fac, full) - T).max() < 1e-12


def test_thrust_curve_ends_and_range():
    """0 N is command 0, thrust_full command 1; thrusts outside are clipped, NaN stays."""
    u = command_from_thrust([-1.0, 0.0, 6.0, 7.0, np.nan], 0.3, 6.0)
    np.testing.assert_array_equal(u[:4], [0.0, 0.0, 1.0, 1.0])
    assert np.isnan(u[4])


def test_px4_order_puts_each_motor_where_px4_has_it():
    """The tool's motors (docs/conventions.md: 1 front left, 2 rear left, 3 rear right,
    4 front right) land in PX4's quad-X slots (1 front right, 2 rear left, 3 front left,
    4 rear right)."""
    tool = {1: "front left", 2: "rear left", 3: "rear right", 4: "front right"}
    px4 = {1: "front right", 2: "rear left", 3: "front left", 4: "rear right"}
    for i, m in enumerate(PX4_MOTOR_ORDER, start=1):
        assert tool[i] == px4[m]
    assert MOTOR_ORDERS["px4"] == PX4_MOTOR_ORDER
    assert slots_from_order(PX4_MOTOR_ORDER) == (2, 1, 3, 0)


# ---------------------------------------------------------------- the config
def test_config_gives_the_controller_px4_outputs(px4_config, paper_table):
    p = controller_params(paper_table, **outputs_from_config(px4_config))
    assert p.motor_slot == (2, 1, 3, 0) and p.normalized
    assert (p.thr_mdl_fac, p.thrust_full) == (0.3, 4.0)


def test_default_outputs_are_unchanged(paper_config, paper_table):
    """Without [firmware] output keys: thrusts in N, motors T1..T4 (the identity)."""
    p = controller_params(paper_table)
    T = np.array([[0.5, 1.0, 1.5, 2.0]])
    np.testing.assert_array_equal(p.commands_from_thrust(T), T)
    np.testing.assert_array_equal(p.thrust_from_commands(T), T)


@pytest.mark.parametrize("values,key", [
    ({"firmware.thr_mdl_fac": 0.3}, "firmware.thr_mdl_fac"),  # without normalized
    ({"firmware.thrust_max_N": 4.0}, "firmware.thrust_max_N"),
    ({"firmware.motor_order": "ardupilot"}, "firmware.motor_order"),
    ({"firmware.command": "pwm"}, "firmware.command"),
    ({"firmware.command": "normalized", "firmware.thr_mdl_fac": 1.5}, "firmware.thr_mdl_fac"),
    ({"firmware.command": "normalized", "firmware.thrust_max_N": 3.0},
     "firmware.thrust_max_N"),  # below vehicle.thrust_max = 3.5 N
])
def test_contradicting_output_keys_name_the_key(paper_config, values, key):
    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        paper_config.with_values(values)


# ---------------------------------------------------------------- C and Python
@pytest.fixture(scope="module")
def flight(paper_config, paper_table):
    """A recorded tilted flight's sensor rows (poses 12 ms late at 200 Hz, noise) and the
    simulation they come from."""
    res = simulate(paper_config, runtime_scheduler(paper_table, "python"),
                   dataclasses.replace(load_scenario("tilted40"), duration=1.0))
    return res, recorded_rows(res)


def _start(ctl, res):
    v0 = np.gradient(res.p_I[:3], res.t[:3], axis=0)[0]
    return ctl.reset(res.p_I[0], v0, res.q_IB[0])


@pytest.mark.needs_cc
def test_c_and_python_emit_the_same_px4_commands_and_they_invert_to_the_default_newtons(
        paper_config, px4_config, paper_table, flight, tmp_path):
    """On a recorded flight, with PX4 outputs: the C controller (float32) and the Python
    reference (double) give the same statuses and commands within 1e-5 (measured 3e-6);
    the commands, renumbered back and through the thrust curve, are the default export's
    thrusts of the same C controller within 1e-4 N (float32 rounding of the curve), and
    the Python reference's within 1e-9 N of its default."""
    res, rows = flight
    base = controller_params(paper_table, pose_delay=0.012)
    px4 = controller_params(paper_table, **outputs_from_config(px4_config), pose_delay=0.012)
    table = runtime_data(paper_table)
    c_n = CController(table, base, build_dir=tmp_path / "n")
    c_p = CController(table, px4, build_dir=tmp_path / "p")
    py_n, py_p = (Controller(p, Interpolator(table)) for p in (base, px4))
    for ctl in (c_n, c_p, py_n, py_p):
        _start(ctl, res)
    T_c, S_c, _ = c_n.run(rows)
    U_c, S_cp, _ = c_p.run(rows)
    T_py, _, _ = py_n.run(rows)
    U_py, S_pyp, _ = py_p.run(rows)
    np.testing.assert_array_equal(S_cp, S_c)
    np.testing.assert_array_equal(S_cp, S_pyp)
    assert not np.any(S_c & CTRL_IDLE)
    assert np.all((U_c >= 0) & (U_c <= 1))
    assert np.abs(U_c - U_py).max() < 1e-5
    assert np.abs(px4.thrust_from_commands(U_c) - T_c).max() < 1e-4
    assert np.abs(px4.thrust_from_commands(U_py) - T_py).max() < 1e-9
    # PX4's motor 1 (slot 0) is the tool's T4, front right
    np.testing.assert_allclose(U_py[:, 0], command_from_thrust(T_py[:, 3], 0.3, 4.0),
                               rtol=0, atol=1e-12)


@pytest.mark.needs_cc
@pytest.mark.parametrize("field,value", [("motor_slot", (0, 1, 1, 3)),
                                         ("motor_slot", (0, 1, 2, 4)),
                                         ("thrust_full", 3.0),
                                         ("thr_mdl_fac", 1.5)])
def test_c_runtime_refuses_bad_output_fields(px4_config, paper_table, tmp_path, field, value):
    """gs_ctrl_init answers GS_BAD_ARG for a motor_slot that is no permutation of 0..3, a
    thrust at full command below thrust_max and a curve outside 0..1."""
    px4 = controller_params(paper_table, **outputs_from_config(px4_config))
    p = dataclasses.replace(px4, **{field: value})
    with pytest.raises(RuntimeError, match="refused"):
        CController(paper_table, p, build_dir=tmp_path)


# ---------------------------------------------------------------- in the loop
@pytest.mark.needs_cc
def test_simulation_in_firmware_mode_flies_the_same_with_px4_outputs(paper_config,
                                                                     px4_config, paper_table):
    """The tilted flight with the C controller in the loop, PX4 outputs turned back into
    thrusts by the same curve (the flight stack's mixer): the states stay within 1e-4 of
    the default export's flight (measured 3e-6) and the metrics within 1 %."""
    sched = runtime_scheduler(paper_table, "c")
    scn = dataclasses.replace(load_scenario("tilted40"), duration=1.5)
    r_n = simulate(paper_config, sched, scn, controller="firmware")
    r_p = simulate(px4_config, sched, scn, controller="firmware")
    assert np.abs(r_p.z - r_n.z).max() < 1e-4
    m_n, m_p = metrics(r_n), metrics(r_p)
    for k in ("rms_out_of_plane_m", "rms_along_track_m", "rms_speed_error_mps"):
        assert abs(m_p[k] - m_n[k]) <= 0.01 * m_n[k] + 1e-9, (k, m_p[k], m_n[k])


# ---------------------------------------------------------------- export
def test_export_c_options_write_px4_outputs(tmp_path):
    """`gainsched export-c --motor-order px4 --command normalized --thr-mdl-fac 0.3`
    writes them into NAME_control.h; a curve without normalised outputs is one line,
    exit 2, nothing written."""
    table = tmp_path / "paper.h5"
    shutil.copy(PAPER_H5, table)
    cmd = [sys.executable, "-m", "gainsched", "export-c", str(table), "--no-code-size"]
    out = tmp_path / "px4"
    r = subprocess.run([*cmd, "-o", str(out), "--motor-order", "px4", "--command",
                        "normalized", "--thr-mdl-fac", "0.3"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    text = (out / "paper_control.h").read_text()
    assert '#define PAPER_MOTOR_ORDER "px4"' in text and "{2u, 1u, 3u, 0u}" in text
    assert '#define PAPER_COMMAND "normalized"' in text and "0.3f, /* thr_mdl_fac" in text
    bad = tmp_path / "bad"
    r = subprocess.run([*cmd, "-o", str(bad), "--thr-mdl-fac", "0.3"], capture_output=True,
                       text=True)
    assert r.returncode == 2 and "firmware.thr_mdl_fac" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not bad.exists()
