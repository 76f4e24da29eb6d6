"""Reader identity, configuration and scaling for every range and rate the readers offer.

The datasheet values (WHO_AM_I, sensitivities, rates, register fields, temperature formulas) are
written out here from shared/hardware-reference.md, not read from gyrocal.drivers.imu.chips.
"""

import errno
import math
import warnings

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate
from gyrocal.drivers.errors import BusError, ConfigurationError, DeviceIdentityError
from gyrocal.drivers.imu import (
    MODELS,
    BusOpenError,
    ChipIdentityError,
    ChipNotice,
    ImuStateError,
    LSM9DS1Reader,
    MPU9250Reader,
    open_bus,
    open_imu,
)

DEG = math.pi / 180
QUIET = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)

# MPU-9250 (§1.4, §1.5): range -> LSB per °/s; DLPF bandwidth -> DLPF_CFG
MPU_LSB_PER_DPS = {250: 131.0, 500: 65.5, 1000: 32.8, 2000: 16.4}
MPU_FS_SEL = {250: 0, 500: 1, 1000: 2, 2000: 3}
MPU_DLPF_CFG = {184: 1, 92: 2, 41: 3, 20: 4, 10: 5, 5: 6}
# LSM9DS1 (§2.3, §2.4): range -> mdps per LSB and FS_G; ODR -> ODR_G
LSM_MDPS_PER_LSB = {245: 8.75, 500: 17.50, 2000: 70.0}
LSM_FS_G = {245: 0b00, 500: 0b01, 2000: 0b11}
LSM_ODR_G = {14.9: 1, 59.5: 2, 119: 3, 238: 4, 476: 5, 952: 6}


def rig(model, truth=QUIET, omega=(0.0, 0.0, 0.0), **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu(model, clock, ConstantRate(omega), truth,
                                  **{"subsamples": 1, **kw})
    return clock, bus, addr


def stream(reader, clock, seconds, seed=0, step=(0.01, 0.03)):
    """Read every ``step`` (10-30 ms) for ``seconds``; return the concatenated batches' arrays."""
    out = []
    rng = np.random.default_rng(seed)
    end = clock.monotonic() + seconds
    while clock.monotonic() < end:
        clock.sleep(rng.uniform(*step))
        out.append(reader.read())
    assert not any(b.gaps for b in out)
    return (np.concatenate([b.t for b in out]), np.concatenate([b.rate for b in out]),
            np.concatenate([b.saturated for b in out]),
            np.concatenate([b.temperature_c for b in out]))


# ----------------------------------------------------------------------------- identity


@pytest.mark.parametrize("variant,who", [("mpu9250", 0x71), ("mpu9255", 0x73)])
def test_mpu_family_is_identified(variant, who):
    clock, bus, addr = rig(variant)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = MPU9250Reader(bus, addr, clock=clock)
    assert (r.model, r.chip.who_am_i, r.notice) == (variant, who, None)


def test_mpu6500_is_accepted_with_a_notice():
    clock, bus, addr = rig("mpu6500")
    with pytest.warns(ChipNotice, match="MPU-6500"):
        r = open_imu("mpu9250", bus, addr, clock=clock, range_dps=500, odr_hz=200)
    assert r.model == "mpu6500" and "magnetometer" in r.notice
    assert r.info.manifest()["model"] == "mpu6500"


@pytest.mark.parametrize("who,named", [(0x68, "MPU-6050"), (0x74, "MPU-6515"), (0x12, None)])
def test_mpu_reader_names_a_sibling_or_says_what_it_expected(who, named):
    clock, bus, addr = rig("mpu9250", faults=ChipFaults(who_am_i=who))
    with pytest.raises(ChipIdentityError) as info:
        MPU9250Reader(bus, addr, clock=clock)
    msg = str(info.value)
    assert f"0x{who:02X}" in msg and "0x71" in msg
    assert info.value.who_am_i == who and info.value.address == 0x68
    if named:
        assert named in msg


def test_lsm_reader_names_the_magnetometer_die():
    clock, bus, addr = rig("lsm9ds1", faults=ChipFaults(who_am_i=0x3D))
    with pytest.raises(ChipIdentityError, match="magnetometer"):
        LSM9DS1Reader(bus, addr, clock=clock)


def test_a_chip_of_the_other_family_is_named():
    clock, bus, addr = rig("lsm9ds1")
    with pytest.raises(ChipIdentityError, match="LSM9DS1.*lsm9ds1"):
        MPU9250Reader(bus, addr, clock=clock)
    clock, bus, addr = rig("mpu9250")
    with pytest.raises(ChipIdentityError, match="MPU-9250.*'mpu9250'"):
        LSM9DS1Reader(bus, addr, clock=clock)


def test_nobody_at_the_address_is_a_bus_error_naming_it():
    clock, bus, _ = rig("mpu9250")
    with pytest.raises(BusError) as info:
        MPU9250Reader(bus, 0x69, clock=clock)
    e = info.value
    assert (e.errno, e.address, e.register) == (errno.EREMOTEIO, 0x69, 0x75)
    assert "i2cdetect" in str(e)


def test_bad_addresses_and_models_are_configuration_errors():
    clock, bus, addr = rig("mpu9250")
    with pytest.raises(ConfigurationError, match="0x68 or 0x69"):
        MPU9250Reader(bus, 0x100, clock=clock)
    with pytest.raises(ConfigurationError, match=", ".join(MODELS)):
        open_imu("bmi160", bus, clock=clock, range_dps=250, odr_hz=100)


# ----------------------------------------------------------------------------- configuration


def test_every_mpu_rate_is_written_and_streams_at_that_rate():
    clock, bus, addr = rig("mpu9250", bus_hz=0)
    r = MPU9250Reader(bus, addr, clock=clock, stuck_after_s=None)
    for div in range(256):
        odr = 1000.0 / (1 + div)
        info = r.configure(range_dps=250, odr_hz=odr)
        assert info.odr_hz == pytest.approx(odr, rel=1e-12)
        assert bus.read_byte_data(addr, 0x19) == div  # SMPLRT_DIV
        assert bus.read_byte_data(addr, 0x1B) & 0x03 == 0  # FCHOICE_B = 00: DLPF in use
        dlpf = bus.read_byte_data(addr, 0x1A) & 0x07
        assert 1 <= dlpf <= 6  # internal rate 1 kHz, so SMPLRT_DIV applies
        bandwidth = {v: k for k, v in MPU_DLPF_CFG.items()}[dlpf]
        assert info.lowpass_hz == bandwidth
        # the widest bandwidth below Nyquist (at 40, 20 and 10 Hz not the one at it: it would
        # alias the noise above half the rate in); the narrowest (5 Hz) at 10 Hz and below
        assert bandwidth == max([b for b in MPU_DLPF_CFG if b < odr / 2], default=5)
        t0 = clock.monotonic()
        r.start()
        # drained every 10-30 sample periods (10-30 ms at 1 kHz; the FIFO holds 36 frames), so
        # each rate costs a few drains, not the 50 per second of a fixed 10-30 ms
        t, *_ = stream(r, clock, max(1.0, 40 / odr), seed=div, step=(10 / odr, 30 / odr))
        elapsed = clock.monotonic() - t0
        r.stop()
        assert len(t) == pytest.approx(odr * elapsed, abs=2)  # first one dropped, one in flight


@pytest.mark.parametrize("bandwidth", sorted(MPU_DLPF_CFG))
def test_every_mpu_filter_is_written(bandwidth):
    clock, bus, addr = rig("mpu9250")
    info = open_imu("mpu9250", bus, addr, clock=clock, range_dps=500, odr_hz=1000,
                    lowpass_hz=bandwidth).info
    assert bus.read_byte_data(addr, 0x1A) & 0x07 == MPU_DLPF_CFG[bandwidth]
    assert info.lowpass_hz == bandwidth


@pytest.mark.parametrize("range_dps", sorted(MPU_LSB_PER_DPS))
def test_every_mpu_range_scales_counts_by_the_datasheet_sensitivity(range_dps):
    omega = np.array([0.7, -0.4, 0.1]) * range_dps * DEG
    clock, bus, addr = rig("mpu9250", omega=omega, truth=SensorTruth(
        noise_density_rad_s_sqrt_hz=0.0, temperature_c=40.0))
    r = open_imu("mpu9250", bus, addr, clock=clock, range_dps=range_dps, odr_hz=500,
                 stuck_after_s=None)
    lsb = DEG / MPU_LSB_PER_DPS[range_dps]  # rad/s per count
    assert (bus.read_byte_data(addr, 0x1B) >> 3) & 0x03 == MPU_FS_SEL[range_dps]
    assert r.info.sensitivity_rad_s_per_lsb == pytest.approx(lsb, rel=1e-12)
    assert r.info.full_scale_dps == range_dps
    r.start()
    t, rate, sat, temp = stream(r, clock, 0.5)
    np.testing.assert_allclose(rate, np.broadcast_to(np.rint(omega / lsb) * lsb, rate.shape))
    assert np.all(np.abs(rate - omega) <= lsb / 2 + 1e-12)
    assert not sat.any()
    assert np.all(np.abs(temp - 40.0) <= 0.5 / 333.87 + 1e-12)  # TEMP_OUT/333.87 + 21


@pytest.mark.parametrize("odr", sorted(LSM_ODR_G))
@pytest.mark.parametrize("range_dps", sorted(LSM_MDPS_PER_LSB))
def test_every_lsm_range_and_rate(range_dps, odr):
    omega = np.array([-0.6, 0.3, 0.8]) * range_dps * DEG
    clock, bus, addr = rig("lsm9ds1", omega=omega, truth=SensorTruth(
        noise_density_rad_s_sqrt_hz=0.0, temperature_c=33.0), bus_hz=0)  # exact sample counts
    r = open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=range_dps, odr_hz=odr,
                 stuck_after_s=None)
    ctrl1 = bus.read_byte_data(addr, 0x10)  # CTRL_REG1_G
    assert ctrl1 >> 5 == LSM_ODR_G[odr]
    assert (ctrl1 >> 3) & 0x03 == LSM_FS_G[range_dps]
    lsb = LSM_MDPS_PER_LSB[range_dps] * 1e-3 * DEG
    assert r.info.sensitivity_rad_s_per_lsb == pytest.approx(lsb, rel=1e-12)
    assert r.info.odr_hz == odr
    t0 = clock.monotonic()
    r.start()
    t, rate, sat, temp = stream(r, clock, max(0.5, 40 / odr))
    assert len(t) == pytest.approx(odr * (clock.monotonic() - t0), abs=2)
    assert np.all(np.abs(rate - omega) <= lsb / 2 + 1e-12)
    assert not sat.any()
    assert np.all(temp == 25.0 + round((33.0 - 25.0) * 16) / 16)  # 25 + OUT_TEMP/16


def test_lsm_filters_follow_the_rate():
    clock, bus, addr = rig("lsm9ds1")
    r = LSM9DS1Reader(bus, addr, clock=clock)
    # ST Table 47 at 952 Hz: BW_G 00..11 = 33, 40, 58, 100 Hz (hardware reference §2.3)
    for bw, cutoff in enumerate((33, 40, 58, 100)):
        assert r.configure(500, 952, lowpass_hz=cutoff).lowpass_hz == cutoff
        assert bus.read_byte_data(addr, 0x10) & 0x03 == bw
    assert r.configure(500, 238).lowpass_hz == 78  # widest below 119 Hz
    with pytest.raises(ConfigurationError, match="14, 29, 63, 78"):
        r.configure(500, 238, lowpass_hz=100)


@pytest.mark.parametrize(
    "model,kwargs,match",
    [
        ("mpu9250", {"range_dps": 245, "odr_hz": 100}, "250, 500, 1000, 2000"),
        ("mpu9250", {"range_dps": 250, "odr_hz": 2000}, "SMPLRT_DIV"),
        ("mpu9250", {"range_dps": 250, "odr_hz": 0}, "SMPLRT_DIV"),
        ("mpu9250", {"range_dps": 250, "odr_hz": 1, "lowpass_hz": None}, "3.906"),
        ("mpu9250", {"range_dps": 250, "odr_hz": 100, "lowpass_hz": 250}, "184, 92, 41"),
        ("lsm9ds1", {"range_dps": 250, "odr_hz": 119}, "245, 500, 2000"),
        ("lsm9ds1", {"range_dps": 245, "odr_hz": 100}, "14.9, 59.5, 119, 238, 476, 952"),
    ],
)
def test_impossible_settings_list_the_possible_ones(model, kwargs, match):
    clock, bus, addr = rig(model)
    with pytest.raises(ConfigurationError, match=match):
        open_imu(model, bus, addr, clock=clock, **kwargs)


def test_near_rates_snap_to_the_chip_rate():
    clock, bus, addr = rig("mpu9250")
    assert open_imu("mpu9250", bus, addr, clock=clock, range_dps=250,
                    odr_hz=333).info.odr_hz == pytest.approx(1000 / 3)
    clock, bus, addr = rig("lsm9ds1")
    assert open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=245,
                    odr_hz=15).info.odr_hz == 14.9


def test_bring_up_follows_the_reset_sequence():
    clock, bus, addr = rig("mpu9250")
    r = MPU9250Reader(bus, addr, clock=clock)
    bus.log.clear()
    t0 = clock.monotonic()
    r.configure(500, 1000)
    writes = [(e.register, e.written[0]) for e in bus.log if e.op == "write_byte_data"]
    assert writes[:3] == [(0x6B, 0x80), (0x68, 0x07), (0x6B, 0x01)]  # H_RESET, paths, CLKSEL
    assert clock.monotonic() - t0 >= 0.100 + 0.100 + 0.005 + 0.035  # §1.3 waits
    clock, bus, addr = rig("lsm9ds1")
    r = LSM9DS1Reader(bus, addr, clock=clock)
    bus.log.clear()
    r.configure(500, 952)
    writes = [(e.register, e.written[0]) for e in bus.log if e.op == "write_byte_data"]
    assert writes[0] == (0x22, 0x05)  # CTRL_REG8 = SW_RESET | IF_ADD_INC (§2.6)


def test_a_chip_that_does_not_keep_its_settings_is_refused():
    clock, bus, addr = rig("mpu9250")
    r = MPU9250Reader(bus, addr, clock=clock)
    chip = bus.device(addr)
    chip._write_register = lambda reg, value: None  # a part that ignores every write
    with pytest.raises(DeviceIdentityError, match="read back"):
        r.configure(500, 1000)


def test_info_and_state_errors():
    clock, bus, addr = rig("lsm9ds1")
    r = LSM9DS1Reader(bus, addr, clock=clock)
    with pytest.raises(ImuStateError, match="configure"):
        _ = r.info
    with pytest.raises(ImuStateError, match="configure"):
        r.start()
    with pytest.raises(ImuStateError, match="start"):
        r.read()
    info = r.configure(2000, 952)
    assert info.manifest() == {"model": "lsm9ds1", "odr_hz": 952.0, "full_scale_dps": 2000.0,
                               "sensitivity_rad_s_per_lsb": pytest.approx(70e-3 * DEG, rel=1e-12),
                               "accel_full_scale_g": 4.0,  # LSM9DS1 Table 3: 0.122 mg/LSB
                               "accel_sensitivity_m_s2_per_lsb": pytest.approx(
                                   0.122e-3 * 9.80665, rel=1e-12)}
    assert (r.odr_hz, r.full_scale_dps) == (952.0, 2000.0)
    r.close()
    assert bus.read_byte_data(addr, 0x10) >> 5 == 0  # powered down
    with pytest.raises(ImuStateError, match="closed"):
        r.start()


# ----------------------------------------------------------------------------- opening a bus


class _Raiser:
    def __init__(self, exc):
        self.exc = exc

    def __call__(self, bus):
        raise self.exc


@pytest.mark.parametrize(
    "exc,needles",
    [
        (FileNotFoundError(errno.ENOENT, "No such file"), ["raspi-config", "dtparam=i2c_arm=on"]),
        (PermissionError(errno.EACCES, "Permission denied"), ["i2c` group", "usermod"]),
    ],
)
def test_opening_a_missing_or_forbidden_bus_says_what_to_do(monkeypatch, exc, needles):
    import smbus2

    monkeypatch.setattr(smbus2, "SMBus", _Raiser(exc))
    with pytest.raises(BusOpenError) as info:
        open_bus(1)
    assert info.value.errno == exc.errno
    assert "/dev/i2c-1" in str(info.value)
    for needle in needles:
        assert needle in str(info.value)
    with pytest.raises(BusOpenError):
        MPU9250Reader(1)


def test_a_reader_closes_the_bus_it_opened(monkeypatch):
    import smbus2

    clock, bus, addr = rig("mpu9250")
    monkeypatch.setattr(smbus2, "SMBus", lambda n: bus)
    r = MPU9250Reader(1, clock=clock)
    r.close()
    with pytest.raises(OSError):
        bus.read_byte_data(addr, 0x75)


@pytest.mark.parametrize(
    ("model", "asked", "taken"),
    [("mpu9250", 201.0, 200.0), ("mpu9250", 203.0, None), ("mpu9250", 150.0, None),
     ("lsm9ds1", 120.0, 119.0), ("lsm9ds1", 125.0, None)],
)
def test_an_odr_within_one_percent_is_rounded_to_the_chips_and_farther_is_refused(
    model, asked, taken
):
    # MPU-9250: 1 kHz / (1 + SMPLRT_DIV) with the low-pass filter on; LSM9DS1: its ODR_G table.
    # The rate used is in info.odr_hz (the kit notes the rounding, test_cli_inputs.py).
    clock, bus, addr = rig(model)
    if taken is None:
        with pytest.raises(ConfigurationError, match=f"odr_hz={asked!r} is not an"):
            open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=asked)
    else:
        r = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=asked)
        assert r.info.odr_hz == pytest.approx(taken, rel=1e-12)
