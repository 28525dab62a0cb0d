"""An uncalibrated gyroscope (issue 53): its scale and bias per axis fitted against the
motion capture's rates before any dynamics, never read as a missing effect; written
into ``[sensors]``, which the log reader undoes (the controllers too:
tests/firmware/test_controller.py). Flown on the elastic tether of a real vehicle.

Before it, a gyro 3 % off with biases was accepted as ``thrust_motor + thrust_azimuth``
(empirical thrust terms with CIs of +-5,000): a wrong story written into the config.
"""

from __future__ import annotations

import numpy as np
import pytest

from gainsched.analysis.compare import compare
from gainsched.analysis.diagnose import apply_diagnosis, gyro_calibration
from gainsched.config import config_from_text
from gainsched.errors import InputError
from gainsched.sim.campaign import HIDDEN

from support import REPO, rechecksum

#: the hidden gyro of the campaign: scale and bias per axis (x, y, z)
SCALE = np.array([1.03, 0.97, 1.02])
BIAS = np.array([0.01, -0.008, 0.012])
#: the other effects a diagnosis may accept beside the calibration: the real tether's own
#: stretch (the base truth of these flights)
ALLOWED = {"tether_elasticity"}


def test_the_hidden_gyro_is_the_campaigns():
    """The constants here are the hidden effect's (one truth, checked)."""
    edits = dict((k, v) for _, k, v in HIDDEN["gyro"].sections)
    np.testing.assert_array_equal(edits["gyro_scale"], SCALE)
    np.testing.assert_array_equal(edits["gyro_bias"], BIAS)


def test_a_gyro_off_by_percents_is_found_within_10_percent(diagnosed):
    """Every scale error (s - 1) and every bias within 10 % of the truth, each 95 %
    interval covering it, the held-out residual above noise falling >= 80 %."""
    d = diagnosed("gyro", real_tether=True)
    cal = d.calibration
    assert cal is not None and cal.accepted, cal
    assert np.all(np.abs((cal.scale - 1) - (SCALE - 1)) <= 0.1 * np.abs(SCALE - 1)), cal.scale
    assert np.all(np.abs(cal.bias - BIAS) <= 0.1 * np.abs(BIAS)), cal.bias
    assert np.all(np.abs(cal.scale - SCALE) <= cal.scale_ci + 1e-3)
    assert np.all(np.abs(cal.bias - BIAS) <= cal.bias_ci + 1e-3)
    assert cal.fall >= 0.8
    assert all(cal.off.values())


def test_a_gyro_error_is_not_told_as_a_missing_effect(diagnosed):
    """The dynamics are fitted on the calibrated rates: nothing but the calibration (and
    the real tether's own stretch) is accepted; the verdict starts with the gyro."""
    d = diagnosed("gyro", real_tether=True)
    assert d.applied[0] == "gyro_calibration"
    assert set(d.applied[1:]) <= ALLOWED, d.verdict
    assert d.verdict.startswith("gyro calibration accepted")
    assert d.config.sensors.gyro_scale != (1.0, 1.0, 1.0)  # the model diagnosed has it


def test_a_calibrated_gyro_is_left_alone(diagnosed):
    """Negative control: the same flights with a gyro that reads the rates as they are:
    no calibration parameter is off, nothing is written to [sensors]."""
    d = diagnosed("none", real_tether=True)
    assert d.calibration is not None and not d.calibration.axes_changed, \
        d.calibration.sentence()
    assert "gyro_calibration" not in d.applied
    text = apply_diagnosis(d)
    assert text is None or "[sensors]" not in text


def test_the_applied_calibration_explains_the_rates_residual(paper_config, diagnosed, fly):
    """--apply writes [sensors] (the fitted values, CIs in comments); the config read
    back undoes the gyro: the roll and pitch angular-acceleration residuals of the same
    flights fall (a 3 % scale error is 3 % of every measured angular acceleration), the
    yaw's (noise on these flights) stays within 1 %, and nothing is left to calibrate."""
    d = diagnosed("gyro", real_tether=True)
    text = apply_diagnosis(d)
    assert "[sensors]" in text and "95%" in text
    new = config_from_text(text, "gyro.toml")
    np.testing.assert_allclose(new.sensors.gyro_scale, d.calibration.scale, atol=1e-6)
    logs = fly("gyro", real_tether=True)
    before, after = compare(paper_config, logs), compare(new, logs)
    rms = {a: (before.stats[a].rms, after.stats[a].rms) for a in ("roll", "pitch", "yaw")}
    assert rms["roll"][1] < rms["roll"][0] and rms["pitch"][1] < rms["pitch"][0], rms
    assert all(a <= 1.01 * b for b, a in rms.values()), rms  # the yaw's is noise there
    again = gyro_calibration(new, after.measured)
    assert not again.axes_changed, again.sentence()  # nothing left to calibrate


@pytest.mark.parametrize("edit,key", [
    ("gyro_scale = [1.0, 1.0]", "sensors.gyro_scale"),
    ("gyro_scale = [1.0, 0.1, 1.0]", "sensors.gyro_scale"),
    ("gyro_bias = [0.0, 0.0, 0.9]", "sensors.gyro_bias"),
    ("gyro_offset = [0.0, 0.0, 0.0]", "sensors.gyro_offset"),
])
def test_a_bad_sensors_section_is_refused_naming_the_key(paper_config, edit, key):
    """[sensors]: 3 numbers per key, a scale in [0.5, 2], a bias within +-0.5 rad/s, no
    unknown key: one error naming the file and the key."""
    with pytest.raises(InputError) as err:
        config_from_text(paper_config.text + f"\n[sensors]\n{edit}\n", "bad.toml")
    assert err.value.source == "bad.toml" and err.value.where == key, str(err.value)


def test_a_table_built_before_the_calibration_was_carried_still_loads(tmp_path):
    """A table whose firmware record has no gyro keys (built before they were carried)
    loads with an uncalibrated gyro; a record with a bad calibration is refused naming
    the dataset."""
    import json
    import shutil

    import h5py

    from gainsched.firmware.controller import controller_params
    from gainsched.schedule.tables import load_table

    for name, change, ok in (("old", lambda c: c.pop("gyro_scale") and c.pop("gyro_bias"),
                              True),
                             ("bad", lambda c: c.update(gyro_scale=[1.0, 0.0, 1.0]), False)):
        path = tmp_path / f"{name}.h5"
        shutil.copy(REPO / "tables" / "paper.h5", path)
        with h5py.File(path, "r+") as f:
            rec = json.loads(f["firmware/controller"][()])
            change(rec)
            del f["firmware/controller"]
            f["firmware/controller"] = json.dumps(rec, sort_keys=True)
            rechecksum(f)
        if ok:
            p = controller_params(load_table(path))
            assert p.gyro_scale == (1.0, 1.0, 1.0) and p.gyro_bias == (0.0, 0.0, 0.0)
        else:
            with pytest.raises(InputError, match="gyro_scale"):
                load_table(path)


def test_diagnose_apply_on_the_command_line_writes_the_calibration(fly, tmp_path):
    """``gainsched diagnose CONFIG LOGS --apply -o NEW``: the verdict line starts with
    the gyro, the written line names it, NEW has [sensors] and validates."""
    from click.testing import CliRunner

    from gainsched.cli import cli
    from gainsched.sim.campaign import write_campaign

    logs = write_campaign(tmp_path / "logs", fly("gyro", real_tether=True))
    new = tmp_path / "new.toml"
    res = CliRunner().invoke(cli, ["diagnose", str(REPO / "configs" / "paper.toml"),
                                   *map(str, logs), "--apply", "-o", str(new)])
    assert res.exit_code == 0, res.output
    assert "gyro calibration accepted" in res.output
    assert f"wrote {new} (gyro_calibration" in res.output, res.output
    cfg = config_from_text(new.read_text(), str(new))
    assert np.all(np.abs(np.array(cfg.sensors.gyro_scale) - SCALE) < 0.01)
