"""The emulated LSM6DSOX at register level and its reader, against datasheet DS12814.

Register addresses, tags, sensitivities and the FIFO word layout are written out here from the
datasheet (and ST's lsm6dsox_reg.h and the kernel's st_lsm6dsx driver, which agree), not taken
from the driver's tables.
"""

import math
import warnings

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import ChipFaults, SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion
from gyrocal.drivers.imu import ChipIdentityError, ChipNotice, open_imu

DEG = math.pi / 180
QUIET = SensorTruth(noise_density_rad_s_sqrt_hz=0.0)

FUNC_CFG_ACCESS, FIFO_CTRL3, FIFO_CTRL4, WHO_AM_I = 0x01, 0x09, 0x0A, 0x0F
CTRL2_G, CTRL3_C, CTRL10_C, OUT_TEMP_L, OUTX_L_G = 0x11, 0x12, 0x19, 0x20, 0x22
FIFO_STATUS1, FIFO_STATUS2, TIMESTAMP0, FIFO_DATA_OUT_TAG = 0x3A, 0x3B, 0x40, 0x78
# FS_G code -> mdps/LSB (DS12814 Table 2); "125" is CTRL2_G.FS_125
MDPS_PER_LSB = {0b00: 8.75, 0b01: 17.50, 0b10: 35.0, 0b11: 70.0}


def lsm(truth=QUIET, motion=None, **kw):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("lsm6dsox", clock, motion or ConstantRate(), truth,
                                  **{"subsamples": 1, **kw})
    return clock, bus, addr, bus.device(addr)


def le16(lo, hi):
    return int.from_bytes(bytes((lo, hi)), "little", signed=True)


def test_identity_address_and_reset_values():
    _, bus, addr, chip = lsm()
    assert addr == 0x6A and chip.family.addresses == (0x6A, 0x6B)
    assert bus.read_byte_data(addr, WHO_AM_I) == 0x6C
    assert bus.read_byte_data(addr, CTRL3_C) == 0x04  # IF_INC
    assert bus.read_byte_data(addr, CTRL2_G) == 0x00 and chip.true_period_s is None


def test_pages_and_software_reset():
    _, bus, addr, chip = lsm()
    bus.write_byte_data(addr, FUNC_CFG_ACCESS, 0x80)  # embedded-functions page
    assert bus.read_byte_data(addr, WHO_AM_I) != 0x6C
    bus.write_byte_data(addr, CTRL2_G, 0x44)  # lands on the page, not in CTRL2_G
    bus.write_byte_data(addr, FUNC_CFG_ACCESS, 0x00)
    assert bus.read_byte_data(addr, CTRL2_G) == 0x00
    bus.write_byte_data(addr, CTRL2_G, 0x44)
    bus.write_byte_data(addr, CTRL3_C, 0x05)  # SW_RESET | IF_INC
    assert bus.read_byte_data(addr, CTRL2_G) == 0x00 and bus.read_byte_data(addr, CTRL3_C) == 4


@pytest.mark.parametrize("fs, full_scale", [(0b00, 250), (0b01, 500), (0b10, 1000),
                                            (0b11, 2000), ("125", 125)])
def test_gyro_output_carries_the_datasheet_sensitivity(fs, full_scale):
    omega = np.array([0.4, -0.3, 0.2]) * full_scale * DEG
    clock, bus, addr, _ = lsm(motion=ConstantRate(omega))
    ctrl2 = (0x4 << 4) | (0x02 if fs == "125" else fs << 2)  # 104 Hz
    bus.write_byte_data(addr, CTRL2_G, ctrl2)
    clock.sleep(0.05)
    raw = bus.read_i2c_block_data(addr, OUTX_L_G, 6)
    counts = [le16(raw[i], raw[i + 1]) for i in (0, 2, 4)]
    mdps = 4.375 if fs == "125" else MDPS_PER_LSB[fs]
    np.testing.assert_array_equal(counts, np.rint(omega / DEG * 1000.0 / mdps))


def test_temperature_register():
    clock, bus, addr, _ = lsm(SensorTruth(noise_density_rad_s_sqrt_hz=0.0, temperature_c=31.0))
    bus.write_byte_data(addr, CTRL2_G, 0x40)
    clock.sleep(0.05)
    lo, hi = bus.read_i2c_block_data(addr, OUT_TEMP_L, 2)
    assert le16(lo, hi) == 6 * 256  # 256 LSB/°C, 0 at 25 °C


def start_fifo(bus, addr, odr_code=0x7, mode=0b001, ts=True):
    bus.write_byte_data(addr, CTRL10_C, 0x20 if ts else 0)  # TIMESTAMP_EN
    bus.write_byte_data(addr, CTRL2_G, (odr_code << 4) | (0b01 << 2))  # ±500 °/s
    bus.write_byte_data(addr, FIFO_CTRL3, odr_code << 4)  # BDR_GY
    bus.write_byte_data(addr, FIFO_CTRL4, (0b01 << 6 if ts else 0) | mode)


def drain(bus, addr):
    s1, s2 = bus.read_i2c_block_data(addr, FIFO_STATUS1, 2)
    words = ((s2 & 0x03) << 8) | s1
    data = b""
    while len(data) < 7 * words:
        data += bytes(bus.read_i2c_block_data(addr, FIFO_DATA_OUT_TAG,
                                              min(28, 7 * words - len(data))))
    return np.frombuffer(data, dtype=np.uint8).reshape(words, 7), s2


def test_tagged_fifo_words_and_timestamps():
    omega = np.array([1.0, -0.5, 0.25])
    truth = SensorTruth(noise_density_rad_s_sqrt_hz=0.0, clock_ppm=-4000)
    clock, bus, addr, _ = lsm(truth, ConstantRate(omega))
    start_fifo(bus, addr)  # 833 Hz, timestamp with every batch, FIFO mode
    clock.sleep(0.0125)
    words, _ = drain(bus, addr)
    tags = words[:, 0] >> 3
    assert len(words) % 2 == 0 and len(words) >= 18
    assert list(tags[:4]) == [0x04, 0x01, 0x04, 0x01]  # TIMESTAMP, GYRO_NC in turn
    assert np.all(tags[0::2] == 0x04) and np.all(tags[1::2] == 0x01)
    cnt = (words[1::2, 0] >> 1) & 0x03
    assert np.all(np.diff(cnt) % 4 == 1)  # TAG_CNT counts the time slots modulo 4
    gyro = words[1::2, 1:7].copy().view("<i2")
    np.testing.assert_array_equal(gyro, np.tile(np.rint(omega / DEG * 1000 / 17.5),
                                                (len(gyro), 1)))
    stamps = words[0::2, 1:5].copy().view("<u4").astype(np.int64).ravel()
    # 833 Hz is 1.2 ms = 48 LSBs of 25 µs on the chip's own clock, whatever its error
    assert set(np.diff(stamps)) == {48}
    live = int.from_bytes(bytes(bus.read_i2c_block_data(addr, TIMESTAMP0, 4)), "little")
    # the live counter runs on: the last sample counted, plus the drain's own bus time
    assert 0 < (live - stamps[-1]) * 25e-6 < 0.01


def test_fifo_mode_stops_when_full_and_latches_the_overrun():
    clock, bus, addr, chip = lsm(motion=ConstantRate((0.1, 0.2, 0.3)))
    start_fifo(bus, addr)
    clock.sleep(0.5)  # 416 samples = 832 words: 512 fit
    s2 = bus.read_byte_data(addr, FIFO_STATUS2)
    assert s2 & 0x20 and s2 & 0x08 and s2 & 0x40  # FULL_IA, OVR_LATCHED, OVR_IA
    assert not bus.read_byte_data(addr, FIFO_STATUS2) & 0x08  # the latch clears when read
    words, _ = drain(bus, addr)
    assert len(words) == 512
    assert set(np.diff(words[0::2, 1:5].copy().view("<u4").astype(int).ravel())) == {48}
    bus.write_byte_data(addr, FIFO_CTRL4, 0x00)  # bypass empties it
    assert chip.fifo_level == 0


def wave():
    a = 200 * DEG
    return FunctionMotion(lambda t: a * np.column_stack(
        [np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.3 * t), np.sin(2 * np.pi * 0.3 * t)]))


def open_lsm(bus, addr, clock, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChipNotice)
        return open_imu("lsm6dsox", bus, addr, clock=clock, **{"range_dps": 500, "odr_hz": 833,
                                                                **kw})


def test_the_shared_identity_is_said_once():
    clock, bus, addr, _ = lsm()
    with pytest.warns(ChipNotice, match="LSM6DSO, LSM6DSOX"):
        r = open_imu("lsm6dsox", bus, addr, clock=clock, range_dps=2000, odr_hz=104)
    assert r.notice and r.info.odr_hz == pytest.approx(6666.67 / 64, rel=1e-4)


def test_a_word_lost_inside_the_fifo_is_a_gap_of_one_without_a_restart():
    motion = wave()
    # the samples compared with the motion as it is: the gyro chain's filter off
    clock, bus, addr, chip = lsm(QUIET, motion, output_filter=False)
    reader = open_lsm(bus, addr, clock)
    reader.start()
    batches = []
    for _ in range(50):
        clock.sleep(0.01)
        batches.append(reader.read())
    chip.fifo_level  # noqa: B018 - bring the FIFO up to date
    for _ in range(3):  # the timestamp, gyro and accelerometer words of the second waiting
        del chip._fifo[3]  # sample are lost
    enables = len(chip.fifo_enables)
    for _ in range(50):
        clock.sleep(0.01)
        batches.append(reader.read())
    gaps = [g for b in batches for g in b.gaps]
    assert len(gaps) == 1 and gaps[0].samples == 1 and "timestamps" in gaps[0].reason
    assert len(chip.fifo_enables) == enables
    index = np.concatenate([b.index for b in batches])
    ks = chip.fifo_enables[0] + 1 + index
    lsb = 17.5e-3 * DEG
    expect = np.rint(motion.rate(chip.sample_time(ks)) / lsb) * lsb
    np.testing.assert_allclose(np.concatenate([b.rate for b in batches]), expect, atol=1e-12)


def test_a_chip_left_on_another_page_is_found_and_siblings_are_named():
    clock, bus, addr, _ = lsm()
    bus.write_byte_data(addr, FUNC_CFG_ACCESS, 0x40)  # sensor-hub page
    assert open_lsm(bus, addr, clock).model == "lsm6dsox"
    clock, bus, addr, _ = lsm(faults=ChipFaults(who_am_i=0x6B))
    with pytest.raises(ChipIdentityError, match="ISM330DHCX"):
        open_lsm(bus, addr, clock)


def test_an_lsm6dsox_where_an_lsm9ds1_was_configured_is_named():
    clock, bus, addr, _ = lsm(address=0x6B)
    with pytest.raises(ChipIdentityError, match=r"LSM6DSOX.*use model 'lsm6dsox'"):
        open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=500, odr_hz=238)


def test_rates_offered_and_refused():
    from gyrocal.drivers.errors import ConfigurationError

    clock, bus, addr, _ = lsm()
    with pytest.raises(ConfigurationError, match="26, 52, 104, 208, 416, 833 Hz"):
        open_lsm(bus, addr, clock, odr_hz=1666)
    # AN5192 Table 14 at 833 Hz: LPF1 off 295.5 Hz; FTYPE 000..111 239.2 .. 12.5 Hz
    with pytest.raises(ConfigurationError, match="at 833 Hz; choose one of 295.5, 281.8, 239.2"):
        open_lsm(bus, addr, clock, lowpass_hz=50)
