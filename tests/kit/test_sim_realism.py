"""``--sim``'s realism knobs: every effect on by default with a truth line, each one off on
request, and a clear error for an effect that does not exist."""

import math

import numpy as np
import pytest

from gyrocal.kit.cli import main
from gyrocal.kit.config import default_config
from gyrocal.kit.sim import REALISM_EFFECTS, SIM_CLOCK_PPM, build_sim


def test_every_effect_is_on_by_default_with_a_truth_line():
    sim = build_sim(default_config(), seed=3)
    lines = sim.truth_manifest()["realism"]
    assert set(lines) == set(REALISM_EFFECTS)
    assert all(v != "off" for v in lines.values())
    assert 0 < abs(sim.truth.clock_ppm) <= SIM_CLOCK_PPM
    g = np.array(lines["g-sensitivity"]["matrix_rad_s_per_g"])
    assert np.max(np.abs(g)) <= math.radians(0.1)  # the datasheet's typical 0.1 °/s/g
    assert sim.jig.wobble_rad > 0 and np.any(sim.jig.lever_arm_m)
    assert sim.port.model_timing


def test_off_gives_the_papers_sensor():
    sim = build_sim(default_config(), seed=3, realism=())
    assert all(v == "off" for v in sim.truth_manifest()["realism"].values())
    r = sim.truth.realism
    assert (r.bias_instability_rad_s, r.rate_random_walk_rad_s_sqrt_s, r.dlpf_delay,
            r.specific_force) == (0.0, 0.0, False, False)
    assert not np.any(r.g_sensitivity_rad_s_per_g)
    assert sim.truth.clock_ppm == 0.0 and sim.jig.wobble_rad == 0.0
    assert not sim.port.model_timing


@pytest.mark.parametrize("effect", list(REALISM_EFFECTS))
def test_each_effect_turns_off_alone(effect):
    on = [e for e in REALISM_EFFECTS if e != effect]
    lines = build_sim(default_config(), seed=3, realism=on).truth_manifest()["realism"]
    assert [k for k, v in lines.items() if v == "off"] == [effect]


def test_an_unknown_effect_is_a_usage_error(tmp_path, capsys):
    code = main(["calibrate", "--sim", "--sim-without", "gremlins", "--quiet",
                 "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "'gremlins'" in err and "coloured-noise" in err
    assert not (tmp_path / "o" / "calibration.json").exists()


# each chip's datasheet figures, written out here (PS-MPU-9250A-01 Table 1, DocID025715 Rev 3
# Table 3 (none: the MPU-9250's stand in), DS-000189 Table 1, DS-000347 Table 1, DS12814 Table 2)
CHIP_FIGURES = {"mpu9250": (0.01, 0.1), "lsm9ds1": (0.01, 0.1), "icm20948": (0.015, 0.1),
                "icm42688p": (0.0028, 0.1), "lsm6dsox": (0.0038, 0.1)}


@pytest.mark.parametrize("model", sorted(CHIP_FIGURES))
def test_the_emulated_sensor_has_its_chips_figures(model):
    cfg = default_config()
    cfg["imu"]["model"] = model
    cfg["imu"]["address"] = 0
    sim = build_sim(cfg, seed=3)
    density, g_sens = CHIP_FIGURES[model]
    np.testing.assert_allclose(sim.truth.noise_density_rad_s_sqrt_hz, math.radians(density))
    g = np.array(sim.truth_manifest()["realism"]["g-sensitivity"]["matrix_rad_s_per_g"])
    assert math.radians(0.5 * g_sens) < np.max(np.abs(g)) <= math.radians(g_sens)
    assert sim.truth.realism.bias_instability_rad_s == pytest.approx(
        math.radians(10.0) / 3600.0)  # the stated assumption (no datasheet gives it)
    assert sim.chip.output_filter  # the dlpf effect: the chip's own filter, as configured
    # its order in the manifest: the ICM-42688-P's UI filter is second order at reset
    # (DS-000347 GYRO_CONFIG1 = 0x16, GYRO_UI_FILT_ORD = 01), the others' first-order stand-ins
    assert sim.truth_manifest()["realism"]["dlpf"]["order"] == (2 if model == "icm42688p" else 1)
    assert not build_sim(cfg, seed=3, realism=[]).chip.output_filter
