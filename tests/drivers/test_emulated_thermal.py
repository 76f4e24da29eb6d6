"""The emulated chip's temperature (issue 13): ambient profiles, the self-heating warm-up, the
temperature coefficients within the datasheets' ranges, and the registers that report them.

Formulas and datasheet figures are written out here, not taken from the emulator's tables:
MPU-9250 TEMP_OUT = (T − 21) · 333.87 (hardware reference §1.6), ZRO variation ±30 °/s and
sensitivity ±4 % over −40…85 °C (PS-MPU-9250A-01 §3.1).
"""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate
from gyrocal.drivers.emulated.thermal import (
    DieTemperature,
    draw_thermal_coefficients,
    parse_ambient,
)

DEG = math.pi / 180
PWR_MGMT_1, SMPLRT_DIV, CONFIG, GYRO_CONFIG = 0x6B, 0x19, 0x1A, 0x1B
TEMP_OUT_H, GYRO_XOUT_H = 0x41, 0x43


def be16(hi, lo):
    v = (hi << 8) | lo
    return v - 65536 if v & 0x8000 else v


@pytest.mark.parametrize("spec, t, expect", [
    ("25", [0.0, 1e4], [25.0, 25.0]),
    ("ramp:20:30:600", [0.0, 300.0, 600.0, 5000.0], [20.0, 25.0, 30.0, 30.0]),
    ("ramp:30:20:100", [50.0], [25.0]),
    ("soak:10:25:200", [0.0, 200.0, 1e5], [10.0, 25.0 - 15.0 * math.exp(-1.0), 25.0]),
])
def test_ambient_profiles(spec, t, expect):
    np.testing.assert_allclose(parse_ambient(spec)(np.array(t)), expect, rtol=1e-12)
    assert parse_ambient(parse_ambient(spec).spec()) == parse_ambient(spec)


@pytest.mark.parametrize("spec, what", [
    ("warm", "not numbers"), ("ramp:20:30", "not understood"), ("ramp:a:30:60", "numbers"),
    ("ramp:20:30:0", "positive"), ("500", "-60..150"), ("soak:20:30:-5", "positive"),
])
def test_bad_ambient_profiles_say_what_is_wrong(spec, what):
    with pytest.raises(ValueError, match=what) as info:
        parse_ambient(spec)
    assert "ramp:T0:T1:SECONDS" in str(info.value) or what in ("positive", "-60..150")


def test_self_heating_is_a_first_order_rise_from_power_on():
    die = DieTemperature(parse_ambient("22"), self_heating_c=4.0, time_constant_s=120.0,
                         power_on_s=10.0)
    got = die(np.array([0.0, 10.0, 130.0, 10.0 + 1e5]))
    np.testing.assert_allclose(got, [22.0, 22.0, 22.0 + 4.0 * (1 - math.exp(-1)), 26.0])
    with pytest.raises(ValueError, match="self-heating"):
        DieTemperature(parse_ambient("22"), self_heating_c=-1.0)


@pytest.mark.parametrize("seed", range(40))
def test_drawn_coefficients_stay_within_the_mpu9250_datasheet(seed):
    c = draw_thermal_coefficients(seed, "mpu9250")
    dt = np.linspace(-40.0, 85.0, 251) - 25.0
    bias = c["bias_temp_coeff_rad_s_per_c"] * dt[:, None] + \
        c["bias_temp_quad_rad_s_per_c2"] * dt[:, None] ** 2
    span = bias.max(axis=0) - bias.min(axis=0)  # the bias's variation over the range
    assert np.all(span / 2 <= 30.0 * DEG)  # ±30 °/s
    assert np.all(np.abs(c["scale_temp_coeff_per_c"]) * 62.5 <= 0.04)  # ±4 % about mid-range
    assert draw_thermal_coefficients(seed)["bias_temp_coeff_rad_s_per_c"].tolist() == \
        c["bias_temp_coeff_rad_s_per_c"].tolist()  # the seed decides


# Per-°C datasheet figures written out here (zero-rate level change, dps/°C; sensitivity change,
# %/°C): ICM-20948 DS-000189 Table 1 (±0.05 dps/°C; ±3 % over −40…85 °C, i.e. 0.048 %/°C about
# mid-range), ICM-42688-P DS-000347 Table 1 (±0.005 dps/°C, ±0.005 %/°C), LSM6DSOX DS12814
# Table 2 (±0.01 dps/°C; sensitivity: the LSM6DSO32's ±0.005 %/°C), LSM9DS1 DocID025715 Table 3
# (±0.03 dps/°C; sensitivity ±2 % over −40…85 °C, i.e. 0.032 %/°C).
PER_DEGREE = {"icm20948": (0.05, 3.0 / 62.5), "icm42688p": (0.005, 0.005),
              "lsm6dsox": (0.01, 0.005), "lsm9ds1": (0.03, 2.0 / 62.5)}


@pytest.mark.parametrize("model", sorted(PER_DEGREE))
@pytest.mark.parametrize("seed", range(10))
def test_the_other_chips_slopes_stay_within_their_per_degree_figures(model, seed):
    """Within ±15 °C of 25 °C (a warm-up's range) the drawn bias slope and scale coefficient of
    each chip stay within its datasheet's per-°C figure."""
    zro, sens = PER_DEGREE[model]
    c = draw_thermal_coefficients(seed, model)
    dt = np.linspace(-15.0, 15.0, 61)[:, None]
    slope = c["bias_temp_coeff_rad_s_per_c"] + 2 * c["bias_temp_quad_rad_s_per_c2"] * dt
    assert np.all(np.abs(slope) <= zro * DEG)
    assert np.all(np.abs(c["scale_temp_coeff_per_c"]) <= sens / 100)
    assert np.any(np.abs(c["bias_temp_coeff_rad_s_per_c"]) > 0.05 * zro * DEG)  # not zero


def test_coefficients_differ_by_seed_and_unknown_models_are_refused():
    a, b = draw_thermal_coefficients(1), draw_thermal_coefficients(2)
    assert not np.allclose(a["bias_temp_coeff_rad_s_per_c"], b["bias_temp_coeff_rad_s_per_c"])
    with pytest.raises(ValueError, match="no temperature figures"):
        draw_thermal_coefficients(0, "bmi088")


def test_registers_report_die_temperature_bias_and_scale_of_the_warm_up():
    """At a constant rate, GYRO_XOUT and TEMP_OUT follow the die's warm-up through the quadratic
    bias and the scale's temperature coefficient."""
    omega = np.array([0.8, -0.4, 0.2])
    die = DieTemperature(parse_ambient("ramp:15:25:400"), self_heating_c=3.0,
                         time_constant_s=100.0)
    c1, c2, k = (2e-3, -1e-3, 5e-4), (4e-5, 0.0, -3e-5), (3e-4, -2e-4, 0.0)
    truth = SensorTruth(scale=(1.02, 0.98, 1.0), bias=(0.01, -0.02, 0.03),
                        bias_temp_coeff_rad_s_per_c=c1, bias_temp_quad_rad_s_per_c2=c2,
                        scale_temp_coeff_per_c=k, reference_temperature_c=25.0,
                        temperature_c=die, noise_density_rad_s_sqrt_hz=0.0)
    clock = VirtualClock()
    bus, addr = make_emulated_imu("mpu9250", clock, ConstantRate(omega), truth, subsamples=1)
    bus.write_byte_data(addr, PWR_MGMT_1, 0x01)
    bus.write_byte_data(addr, SMPLRT_DIV, 0)
    bus.write_byte_data(addr, CONFIG, 1)
    bus.write_byte_data(addr, GYRO_CONFIG, 2 << 3)  # ±1000 °/s: 32.8 LSB/(°/s)
    for t_read in (5.0, 120.0, 390.0):
        clock.sleep(t_read - clock.monotonic())
        now = clock.monotonic()
        temp_raw = bus.read_i2c_block_data(addr, TEMP_OUT_H, 2)
        raw = bus.read_i2c_block_data(addr, GYRO_XOUT_H, 6)
        T = 15.0 + 10.0 * now / 400.0 + 3.0 * (1 - math.exp(-now / 100.0))
        assert be16(*temp_raw) / 333.87 + 21.0 == pytest.approx(T, abs=0.01)
        dT = T - 25.0
        bias = np.array([0.01, -0.02, 0.03]) + np.array(c1) * dT + np.array(c2) * dT**2
        scale = np.array([1.02, 0.98, 1.0]) * (1 + np.array(k) * dT)
        expect = (omega / scale - bias) / DEG * 32.8
        counts = np.array([be16(raw[i], raw[i + 1]) for i in (0, 2, 4)])
        np.testing.assert_allclose(counts, expect, atol=1.0)


def test_truth_manifest_carries_the_temperature_model():
    die = DieTemperature(parse_ambient("soak:10:25:300"))
    truth = SensorTruth(bias=(0.1, 0.2, 0.3), bias_temp_coeff_rad_s_per_c=(1e-3, 2e-3, 3e-3),
                        bias_temp_quad_rad_s_per_c2=(1e-5, 0.0, 0.0),
                        scale_temp_coeff_per_c=(1e-4, 0.0, 0.0), temperature_c=die)
    t = truth.manifest()["temperature"]
    assert t["reference_c"] == 25.0
    assert t["bias_coeffs"] == [[0.1, 1e-3, 1e-5], [0.2, 2e-3, 0.0], [0.3, 3e-3, 0.0]]
    assert t["scale_coeff_per_c"] == [1e-4, 0.0, 0.0]
    assert t["die"]["ambient"] == "soak:10:25:300"
    assert "temperature" not in SensorTruth().manifest()  # the paper's constant-25 °C sensor
