"""Any chip by name (issue 28): ``--imu-model X`` alone finds the chip's address and runs it at
the output data rate it has nearest the one asked.

The expected rates and addresses are the datasheets' figures, written out here independently of
drivers/imu/chips.py:
- MPU-9250 register map §4.4: SAMPLE_RATE = 1000 Hz / (1 + SMPLRT_DIV) with the DLPF on;
  AD0 low: 0x68.
- ICM-20948 DS-000189 GYRO_SMPLRT_DIV: 1125 Hz / (1 + GYRO_SMPLRT_DIV); AD0 low: 0x68.
- LSM9DS1 DS10888 Table 46 (ODR_G): 14.9, 59.5, 119, 238, 476, 952 Hz; gyro SDO_AG high: 0x6B
  (the breakout boards' default).
- ICM-42688-P DS-000347 GYRO_ODR: 12.5, 25, 50, 100, 200, 500, 1000 Hz; AP_AD0 low: 0x68.
- LSM6DSOX DS12814 CTRL2_G: 104, 208, 416 Hz nominal, actually 6667 Hz / 2^k (40000/6/32 for
  "208"); SA0 low: 0x6A.
"""

import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import make_emulated_imu
from gyrocal.drivers.errors import ConfigurationError
from gyrocal.drivers.imu import chip_addresses, find_address, nearest_offered_rate
from gyrocal.kit.cli import main
from gyrocal.kit.config import apply_overrides, default_config

# model: (default address, rate for 200 Hz asked, rate for 1000 Hz asked, rate for 30 Hz asked)
DATASHEET = {
    "mpu9250": (0x68, 1000 / 5, 1000 / 1, 1000 / 33),
    "icm20948": (0x68, 1125 / 6, 1125 / 1, 1125 / 38),
    "lsm9ds1": (0x6B, 238.0, 952.0, 14.9),  # 30: |14.9-30| = 15.1 < |59.5-30| = 29.5
    "icm42688p": (0x68, 200.0, 1000.0, 25.0),
    "lsm6dsox": (0x6A, 40000 / 6 / 32, 40000 / 6 / 8, 40000 / 6 / 256),
}


@pytest.mark.parametrize("model", sorted(DATASHEET))
def test_the_default_address_and_nearest_rate_are_the_datasheets(model):
    address, at200, at1000, at30 = DATASHEET[model]
    assert chip_addresses(model)[0] == address
    assert nearest_offered_rate(model, 200.0) == pytest.approx(at200, rel=1e-9)
    assert nearest_offered_rate(model, 30.0) == pytest.approx(at30, rel=1e-9)
    assert nearest_offered_rate(model, 1000.0) == pytest.approx(at1000, rel=1e-9)


def test_a_rate_that_is_no_number_of_hz_is_refused():
    with pytest.raises(ConfigurationError, match="positive number"):
        nearest_offered_rate("mpu9250", float("nan"))


def test_the_probe_finds_the_chip_at_its_second_address():
    clock = VirtualClock()
    bus, _ = make_emulated_imu("lsm6dsox", clock, address=0x6B, subsamples=1)
    assert find_address("lsm6dsox", bus) == 0x6B
    # none there: the first address, where the reader says that nothing answers
    assert find_address("icm20948", bus) == 0x68
    make_emulated_imu("lsm6dsox", clock, address=0x6A, subsamples=1, bus=bus)
    with pytest.raises(ConfigurationError, match=r"answers at each of 0x6A, 0x6B; give the one"):
        find_address("lsm6dsox", bus)


def test_the_config_leaves_the_address_to_the_chip():
    cfg = apply_overrides(default_config(), {"imu.model": "lsm6dsox"})
    assert cfg["imu"]["address"] == 0  # 0: the chip's own, resolved where the bus is known


@pytest.mark.parametrize("model", ["icm20948", "lsm6dsox"])
def test_doctor_runs_a_chip_by_name_alone(model, capsys):
    """Fails on the code before issue 28: 200 Hz was refused on an ICM-20948, and the LSM6DSOX
    was looked for at 0x68."""
    address, rate = DATASHEET[model][:2]
    assert main(["doctor", "--sim", "--imu-model", model, "--seconds", "0.3"]) == 0
    captured = capsys.readouterr()
    assert f"it runs at the nearest, {rate:.6g} Hz" in captured.err
    assert f"0x{address:02X}: " in captured.out and f"found {model}" in captured.out


def test_the_sensor_is_resolved_to_the_chips_address_and_rate_with_a_note(capsys):
    from gyrocal.kit.jig import resolve_sensor

    bus, _ = make_emulated_imu("lsm6dsox", VirtualClock(), address=0x6B, subsamples=1)
    sensor = {**default_config()["imu"], "model": "lsm6dsox"}
    chip = resolve_sensor(sensor, bus)
    assert chip["address"] == 0x6B and chip["odr_hz"] == pytest.approx(40000 / 6 / 32)
    assert "answers at its other address, 0x6B" in capsys.readouterr().err
    given = resolve_sensor({**sensor, "address": 0x6A}, bus)  # an address given is kept
    assert given["address"] == 0x6A


@pytest.mark.parametrize("model", sorted(DATASHEET))
def test_init_writes_the_chips_address_and_a_rate_it_has(model, tmp_path, capsys):
    from gyrocal.kit.config import load_config

    path = tmp_path / "gyrocal.toml"
    assert main(["init", str(path), "--imu-model", model]) == 0
    imu = load_config(path)["imu"]
    address, at200 = DATASHEET[model][:2]
    assert (imu["model"], imu["address"]) == (model, address)
    assert imu["odr_hz"] == pytest.approx(at200, rel=1e-12)
    assert nearest_offered_rate(model, imu["odr_hz"]) == imu["odr_hz"]  # no rounding note
