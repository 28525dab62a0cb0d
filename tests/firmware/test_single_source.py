"""The table as the firmware's single source (issue 40): the build writes what the
firmware needs into the table (``firmware/``: the feed-forward's vehicle constants, the
S2 state map, the controller's design parameters), and the header and the controller's
parameters come from the table alone, whatever the model code of the checkout that
exports it. A table of the previous format is refused with a line saying to rebuild.
"""

from __future__ import annotations

import math
import shutil
import subprocess

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from gainsched.cli import cli
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.firmware.cfiles import c_files
from gainsched.firmware.controller import controller_params
from gainsched.firmware.runtime import VehicleConstants, runtime_data
from gainsched.model import reduced, symmetry
from gainsched.model.effects import Drag, registered_effect
from gainsched.schedule import onboard
from gainsched.schedule import tables as tb
from gainsched.schedule.grid import build_grid
from gainsched.schedule.tables import load_table, table_bytes, table_from_bytes

from support import PAPER_H5, REPO, rechecksum, small_config, small_config_text


@pytest.fixture(scope="module")
def lagged():
    """A small table of a config with a motor lag (its 4 thrusts in the LQR state, so
    that the state map and the lag parameters are not trivial) and rotor-free drag."""
    cfg = small_config(name="lagged", **{"effects.motor_lag.tau": 0.03,
                                         "effects.drag.mu1": 0.05,
                                         "effects.drag.mu2": 0.004})
    return cfg, table_bytes(cfg, build_grid(cfg))


def _outputs(data: bytes) -> dict[str, bytes]:
    table = table_from_bytes(data, "lagged.h5")
    return c_files(table, controller_params(table))


def test_the_header_does_not_depend_on_the_model_code(lagged, monkeypatch):
    """Generated again after the model code changed (the drag coefficients, the
    allocation matrix, the mass and the S2 state map of gainsched.model), the header,
    the controller's parameters and the runtime are the same bytes: nothing is
    re-derived at generation. The changes do reach the model (the record computed from
    the config now differs in each part), so a firmware that rebuilt them would differ."""
    cfg, data = lagged
    before = _outputs(data)
    record = table_from_bytes(data).firmware
    monkeypatch.setattr(reduced.Model, "drag_coefficients", lambda self: (0.9, 0.09))
    alloc = reduced.allocation_matrix
    monkeypatch.setattr(reduced, "allocation_matrix", lambda *a: 1.5 * alloc(*a))
    init = reduced.Model.__init__

    def heavier(self, config, effects=None):
        init(self, config, effects)
        self.m = 2.0 * self.m

    monkeypatch.setattr(reduced.Model, "__init__", heavier)
    mirror = symmetry.state_mirror
    monkeypatch.setattr(symmetry, "state_mirror", lambda *a: -mirror(*a))
    changed = onboard._record(cfg)  # in this process, where the patches are
    for part in ("vehicle", "state_map"):
        assert not np.array_equal(getattr(changed, part), getattr(record, part)), part
    assert _outputs(data) == before


def test_the_record_holds_what_the_firmware_used_to_derive(lagged):
    """The record against independent references: the vehicle constants against the
    config's values (mass, g, radius = rho + L_e, the drag coefficients as written,
    J; alloc_inv shares a collective thrust equally and a yaw torque ``4 kappa`` as one
    newton per motor, alternating), the lag's ``lag_keep = exp(-dt / tau)``, and the
    state map S2's signed permutation: signs on the reduced states and the integral, the
    lag's thrusts reversed (T1 <-> T4, T2 <-> T3, as ``P_u`` reverses the inputs)."""
    cfg, data = lagged
    rec = table_from_bytes(data).firmware
    v = VehicleConstants.from_array(rec.vehicle)
    assert (v.m, v.g, v.r) == (cfg.vehicle.mass, cfg.g, cfg.tether.length
                               + cfg.tether.attachment_offset)
    assert (v.mu1, v.mu2, v.min_tension) == (0.05, 0.004, cfg.feasibility.min_tension)
    np.testing.assert_array_equal(v.J, np.asarray(cfg.vehicle.inertia, dtype=float))
    kappa = cfg.vehicle.kappa
    np.testing.assert_allclose(v.alloc_inv @ [4.0, 0, 0, 0], np.ones(4), rtol=1e-12)
    yaw = v.alloc_inv @ [0, 0, 0, 4.0 * kappa]
    np.testing.assert_allclose(np.abs(yaw), np.ones(4), rtol=1e-12)
    np.testing.assert_allclose(yaw, -np.roll(yaw, 1), rtol=1e-12)
    ctl = rec.controller
    assert ctl["n_lag"] == 4 and ctl["lag_keep"] == math.exp(-cfg.control.dt / 0.03)
    assert (ctl["dt"], ctl["rho"], ctl["L_e"]) == (cfg.control.dt, cfg.tether.length,
                                                   cfg.tether.attachment_offset)
    P = rec.state_map
    n = P.shape[0]
    assert n == 15 and np.array_equal(P @ P, np.eye(n))
    np.testing.assert_array_equal(P[11:, 11:], np.eye(4)[::-1])
    np.testing.assert_array_equal(np.abs(P[:11, :11]), np.eye(11))
    assert not np.any(P[:11, 11:]) and not np.any(P[11:, :11])


def _rewrite(path, edit) -> None:
    """Apply ``edit(f)`` to an HDF5 table and recompute its checksums, as the build
    would have written the edited file."""
    with h5py.File(path, "r+") as f:
        edit(f)
        rechecksum(f)


@pytest.fixture
def old_table(tmp_path):
    """tables/paper.h5 as the previous format wrote it: no firmware/ group, schema
    gainsched-table/1, its checksums consistent."""
    path = tmp_path / "paper.h5"
    shutil.copy(PAPER_H5, path)

    def to_previous(f):
        del f["firmware"]
        f.attrs["schema"] = tb.PREVIOUS_SCHEMA

    _rewrite(path, to_previous)
    return path


def test_a_table_of_the_previous_format_is_refused_with_a_line_to_rebuild(old_table):
    with pytest.raises(InputError) as exc:
        load_table(old_table)
    assert str(exc.value) == (
        f"{old_table}: schema: 'gainsched-table/1': built before the firmware record "
        "('gainsched-table/2', docs/table-format.md); rebuild the table (gainsched build "
        "CONFIG)")
    res = CliRunner().invoke(cli, ["export-c", str(old_table), "--no-code-size"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "rebuild the table" in lines[0], res.output
    assert "Traceback" not in res.output


def test_a_table_without_its_firmware_record_names_the_dataset(tmp_path):
    """The new schema without the record (deleted, checksums recomputed): refused,
    naming the missing dataset; a record edited to a non-involution, or a controller
    record with a key missing, names its dataset too."""
    path = tmp_path / "paper.h5"
    for edit, key in (
        (lambda f: f.__delitem__("firmware/vehicle"), "firmware/vehicle: missing dataset"),
        (lambda f: f["firmware/state_map"].__setitem__((0, 0), 2.0),
         "firmware/state_map: must be a signed involutive permutation"),
        (lambda f: f["firmware/controller"].__setitem__((), '{"dt": 0.001}'),
         "firmware/controller: must be a JSON object with the keys"),
    ):
        shutil.copy(PAPER_H5, path)
        _rewrite(path, edit)
        with pytest.raises(InputError, match=key):
            load_table(path)


def test_a_hand_made_table_without_a_record_is_refused_by_the_firmware():
    import dataclasses

    t = dataclasses.replace(load_table(PAPER_H5), firmware=None)
    with pytest.raises(InputError, match=r"firmware: missing: .* rebuild it"):
        runtime_data(t)


def test_the_firmware_package_does_not_import_the_model():
    """What the issue asks to see: no reduced-model import and no Model(...) in
    gainsched/firmware (the import-linter contract enforces the import itself)."""
    res = subprocess.run(["git", "grep", "-n", r"reduced import\|Model(", "gainsched/firmware"],
                         cwd=REPO, capture_output=True, text=True)
    assert res.returncode == 1 and res.stdout == "", res.stdout


class _HullDrag(Drag):
    """A user's pure COG-velocity drag, registered for a build (not built in)."""

    kind = "hull_drag"


def test_a_table_of_a_registered_effect_exports_whole_outside_the_registry(tmp_path):
    """Issue 40: a table whose config names an effect registered in the building process
    used to export without its feed-forward elsewhere. Its record carries the constants:
    outside the registry block (where its config no longer loads) the runtime data have
    the vehicle with both drags summed (paper eq. 10: the registered 0.2 N s/m on the
    config's own), and export-c writes the header with the nominal and the controller."""
    text = small_config_text(**{"name": "hull", "effects.hull_drag.mu1": 0.2})
    with registered_effect(_HullDrag):
        cfg = config_from_text(text, "hull.toml")
        data = table_bytes(cfg, build_grid(cfg))
        base_mu1 = sum(dict(e.params)["mu1"] for e in cfg.effects if e.name == "drag")
    with pytest.raises(InputError, match="unknown effect"):
        config_from_text(text, "hull.toml")
    path = tmp_path / "hull.h5"
    path.write_bytes(data)
    v = VehicleConstants.from_array(runtime_data(load_table(path)).vehicle)
    assert v.mu1 == pytest.approx(base_mu1 + 0.2, rel=1e-6)  # float32 in the runtime data
    res = CliRunner().invoke(cli, ["export-c", str(path), "-o", str(tmp_path / "c"),
                                   "--no-code-size"])
    assert res.exit_code == 0, res.output
    assert "#define HULL_HAS_NOMINAL 1" in (tmp_path / "c" / "hull_gains.h").read_text()
    assert (tmp_path / "c" / "hull_control.h").exists()
