"""The ST chips' filters as their documents give them (issue 26), and every reader's stated gyro
bandwidth the one the emulated chip applies.

LSM6DSOX gyro: the chain's bandwidth per ODR and LPF1/FTYPE setting (AN5192 Rev 5 Table 14,
LSM6DSO32 DocID032891 Rev 1 Table 60, written out below), a sine at that bandwidth keeps 1/√2,
the noise per sample follows the bandwidth, the filter runs on whatever the client's polling,
and it lags a 20 Hz sine by the table's phase. LSM6DSOX accelerometer: LPF2 at ODR / HPCF_XL's
divisor (AN5192 Table 10). LSM9DS1 accelerometer: the anti-aliasing filter per ODR or BW_XL and
the high-resolution low-pass at ODR / DCF's divisor (DocID025715 CTRL_REG6_XL / CTRL_REG7_XL as
ST's lsm9ds1_reg.h and SparkFun transcribe them).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from bench.bench_chips import accel_still_stream, predicted_sigma
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import FunctionMotion
from gyrocal.drivers.imu import READERS, nearest_offered_rate, open_imu

DEG = math.pi / 180
LSM6DSOX_N = 0.0038 * DEG  # DS12814 Table 2, rad/s/√Hz
ODR_417 = 6666.666666666667 / 16  # CTRL2_G code 6 (AN5192 "ODR_Actual", 6667 Hz / 2^k)

# AN5192 Rev 5 Table 14 / DocID032891 Table 60, written out here: ODR code -> (LPF1 off, FTYPE
# 000, 001, ..., 111) bandwidths in Hz, for the rates gyrocal's reader streams
AN5192_TABLE_14 = {
    2: (8.3, 8.3, 8.3, 8.3, 8.3, 8.3, 8.3, 7.8, 6.7),
    3: (16.6, 16.6, 16.6, 16.6, 16.6, 16.7, 16.8, 13.4, 9.7),
    4: (33, 33, 33, 33, 33, 33, 31, 19, 11.5),
    5: (66.8, 67, 67, 67, 67, 62.4, 43.2, 23.1, 12.2),
    6: (135.9, 136.6, 130.5, 120.3, 137.1, 86.7, 48, 24.6, 12.4),
    7: (295.5, 239.2, 192.4, 154.2, 281.8, 96.6, 49.4, 25, 12.5),
}


def test_the_lsm6dsox_gyro_table_is_an5192_table_14():
    from gyrocal.drivers.imu.chips import lsm6dsox_gyro_filter

    for code, row in AN5192_TABLE_14.items():
        assert lsm6dsox_gyro_filter(code, False, 5).bandwidth_hz == row[0]
        for ftype in range(8):
            assert lsm6dsox_gyro_filter(code, True, ftype).bandwidth_hz == row[1 + ftype]


def _lsm6dsox(motion=None, *, truth=None, lowpass_hz=None, seed=0):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("lsm6dsox", clock, motion, truth or SensorTruth(),
                                  subsamples=1, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu("lsm6dsox", bus, addr, clock=clock, range_dps=500, odr_hz=417,
                          lowpass_hz=lowpass_hz)
    return clock, bus, addr, reader


def _stream(clock, reader, seconds: float) -> np.ndarray:
    reader.start()
    chunks = []
    while clock.monotonic() < seconds:
        clock.sleep(0.02)
        chunks.append(reader.read())
    return chunks


# 417 Hz: FTYPE 011 (LPF1 + LPF2 137.1 Hz), 100 (86.7 Hz), 110 (24.6 Hz)
@pytest.mark.parametrize("band,ctrl4,ctrl6", [(137.1, 0x02, 0b011), (86.7, 0x02, 0b100),
                                              (24.6, 0x02, 0b110), (135.9, 0x00, 0b000)])
def test_a_sine_at_the_lsm6dsox_table_bandwidth_keeps_one_over_root_two(band, ctrl4, ctrl6):
    amp = 100 * DEG
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * band * t), 0 * t, 0 * t]))
    clock, bus, addr, reader = _lsm6dsox(motion, lowpass_hz=band)  # the chip's own noise
    assert reader.info.lowpass_hz == band
    assert bus.read_byte_data(addr, 0x13) & 0x02 == ctrl4  # CTRL4_C.LPF1_SEL_G
    assert bus.read_byte_data(addr, 0x15) & 0x07 == ctrl6  # CTRL6_C.FTYPE
    batches = _stream(clock, reader, 1.2)
    t = np.concatenate([b.t for b in batches])
    x = np.concatenate([b.rate[:, 0] for b in batches])
    keep = t > 0.6
    basis = np.column_stack([np.sin(2 * np.pi * band * t), np.cos(2 * np.pi * band * t)])[keep]
    gain = math.hypot(*np.linalg.lstsq(basis, x[keep], rcond=None)[0]) / amp
    assert gain == pytest.approx(1 / math.sqrt(2), abs=0.01)


def test_the_lsm6dsox_gyro_noise_shrinks_with_the_bandwidth():
    sigmas = {}
    for band in (137.1, 86.7, 24.6):
        clock, _, _, reader = _lsm6dsox(lowpass_hz=band, seed=3)
        rate = np.vstack([b.rate for b in _stream(clock, reader, 2.0)])[200:]
        sigma = float(np.mean(np.std(rate, axis=0)))
        # white noise of the chip table's density drawn at 417 Hz through the first-order
        # stand-in at the table's bandwidth; ~2300 samples, 3 axes: a few % at 3.5 standard
        # errors of the narrowest's correlated samples
        assert sigma == pytest.approx(predicted_sigma(LSM6DSOX_N, band, ODR_417), rel=0.07)
        sigmas[band] = sigma
    assert sigmas[24.6] < 0.6 * sigmas[137.1] and sigmas[86.7] < sigmas[137.1]


def test_the_lsm6dsox_filter_runs_on_whatever_the_clients_polling():
    # a 100 °/s step at 0.3 s through FTYPE 110 (24.6 Hz at 417 Hz), read from OUTX_L/H_G
    # (0x22) every sample and every 2.6 samples: the same value at the same sample
    motion = FunctionMotion(lambda t: np.column_stack(
        [np.where(t >= 0.3, 100 * DEG, 0.0), 0 * t, 0 * t]))
    seen = []
    for dt in (1 / ODR_417, 2.6 / ODR_417):
        clock = VirtualClock()
        bus, addr = make_emulated_imu("lsm6dsox", clock, motion,
                                      SensorTruth(noise_sigma_rad_s=0.0), subsamples=1, seed=1)
        chip = bus.device(addr)
        for reg, value in ((0x13, 0x02), (0x15, 0b110), (0x11, 0x64)):  # LPF1, FTYPE, 417 Hz
            bus.write_byte_data(addr, reg, value)
        got = {}
        while clock.monotonic() < 0.45:
            clock.sleep(dt)
            lo, hi = bus.read_i2c_block_data(addr, 0x22, 2)
            got[chip.samples_taken] = int.from_bytes(bytes((lo, hi)), "little", signed=True)
        seen.append((got, chip))
    every, slow = seen[0][0], seen[1][0]
    both = sorted(set(every) & set(slow))
    assert len(both) > 20
    assert max(abs(every[k] - slow[k]) for k in both) <= 1
    # and the step rises over the filter's time constant (6.5 ms), not at once
    ks = np.asarray(sorted(every))
    t = seen[0][1].sample_time(ks)
    got = np.asarray([every[k] for k in ks]) / 57.14  # 17.5 mdps/LSB at ±500 °/s
    rising = got[(t > 0.3) & (t < 0.306)]
    assert rising.size >= 2 and np.all(rising < 70) and got[t > 0.40].min() > 99


# AN5192 Table 14 at 417 Hz, written out: (LPF1_SEL_G, FTYPE) -> phase at 20 Hz, degrees
AN5192_PHASE_417 = {(0, 0): 17.81, (1, 0b011): 21.11, (1, 0b100): 33.75, (1, 0b111): 76.33}


@pytest.mark.parametrize("lpf1,ftype", sorted(AN5192_PHASE_417))
def test_the_lsm6dsox_gyro_lags_a_20_hz_sine_by_the_tables_phase(lpf1, ftype):
    # the emulated path (the first-order stand-in plus a pure delay making up the rest) lags a
    # 20 Hz sine by the table's phase delay, read from the data registers every sample
    f, amp = 20.0, 100 * DEG
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
    clock = VirtualClock()
    bus, addr = make_emulated_imu("lsm6dsox", clock, motion, SensorTruth(), seed=1)
    chip = bus.device(addr)
    for reg, value in ((0x13, 0x02 * lpf1), (0x15, ftype), (0x11, 0x64)):  # 417 Hz, ±500 °/s
        bus.write_byte_data(addr, reg, value)
    ks, xs = [], []
    while clock.monotonic() < 1.0:
        clock.sleep(1 / ODR_417)
        lo, hi = bus.read_i2c_block_data(addr, 0x22, 2)
        xs.append(int.from_bytes(bytes((lo, hi)), "little", signed=True))
        ks.append(chip.samples_taken)
    t = chip.sample_time(np.asarray(ks))
    keep = t > 0.4
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[keep]
    c = np.linalg.lstsq(basis, np.asarray(xs, dtype=float)[keep], rcond=None)[0]
    lag_deg = -math.degrees(math.atan2(c[1], c[0]))
    assert lag_deg == pytest.approx(AN5192_PHASE_417[(lpf1, ftype)], abs=0.3)


def _accel_sigma(model: str, odr: float, write) -> tuple[float, float, object]:
    a, n, chip = accel_still_stream(model, 4.0, odr, write, seed=2)
    return float(np.mean(np.std(a, axis=0))), n, chip


# CTRL1_XL (0x10) bit 1 LPF2_XL_EN; CTRL8_XL (0x17) HPCF_XL in bits 7:5: ODR/4, /20, /100
@pytest.mark.parametrize("hpcf,divisor", [(0b000, 4.0), (0b010, 20.0), (0b100, 100.0)])
def test_the_lsm6dsox_accel_lpf2_is_odr_over_the_table_divisor(hpcf, divisor):
    odr = 6666.666666666667 / 32  # the reader's 208 Hz
    sigma, n, chip = _accel_sigma("lsm6dsox", 208, [(0x10, 0x02, 0x02), (0x17, hpcf << 5)])
    assert chip.accel_filter_setting().bandwidth_hz == pytest.approx(odr / divisor)
    want = predicted_sigma(n, odr / divisor, odr)
    assert sigma == pytest.approx(want, rel=0.08)
    assert sigma < 0.8 * n * math.sqrt(odr)  # below the unfiltered noise (LPF1's ODR/2)


# LSM9DS1 at 238 Hz (the reader's --sim rate): CTRL_REG6_XL (0x20) bits 2:0 BW_SCAL_ODR | BW_XL,
# CTRL_REG7_XL (0x21) HR (bit 7) | DCF (bits 6:5)
@pytest.mark.parametrize("write,band", [
    ([], 105.0),  # BW_SCAL_ODR = 0: 105 Hz at 238 Hz
    ([(0x20, 0x07, 0b111)], 50.0),  # BW_XL 11
    ([(0x21, 0x80 | 0b10 << 5)], 238.0 / 9),  # HR, DCF 10: ODR/9
    ([(0x21, 0x80 | 0b00 << 5)], 238.0 / 50),  # HR, DCF 00: ODR/50
])
def test_the_lsm9ds1_accel_filter_follows_its_registers(write, band):
    sigma, n, chip = _accel_sigma("lsm9ds1", 238, write)
    assert chip.accel_filter_setting().bandwidth_hz == pytest.approx(band)
    tol = 0.08 if band > 20 else 0.2  # ~950 samples, fewer independent the narrower
    assert sigma == pytest.approx(predicted_sigma(n, band, 238.0), rel=tol)


@pytest.mark.parametrize("model", sorted(READERS))
def test_every_readers_stated_bandwidth_is_the_emulated_filters(model):
    # at --sim's rate (200 Hz asked): the reader's lowpass_hz is the emulated chip's cutoff,
    # below half the rate (ICM-42688-P: 80 Hz, GYRO_UI_FILT_BW 2; LSM6DSOX: 67 Hz, FTYPE 000)
    clock = VirtualClock()
    bus, addr = make_emulated_imu(model, clock, seed=0)
    odr = nearest_offered_rate(model, 200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = open_imu(model, bus, addr, clock=clock, range_dps=500, odr_hz=odr)
    reader.start()
    clock.sleep(0.05)
    reader.read()
    chip = bus.device(addr)
    assert reader.info.lowpass_hz == chip.cutoff_hz() < reader.info.odr_hz / 2


def test_an_icm42688p_left_at_odr_over_two_filters_faster_than_its_odr():
    # a third-party driver leaving GYRO_UI_FILT_BW at its reset value 1 at 200 Hz: max(400,
    # 200)/4 = 100 Hz, second order (DS-000347), which the emulator runs at 800 Hz and
    # decimates; a 60 Hz sine keeps the cascade's |H| there (0.87), not all of it
    f, amp = 60.0, 100 * DEG
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
    clock = VirtualClock()
    bus, addr = make_emulated_imu("icm42688p", clock, motion,
                                  SensorTruth(noise_sigma_rad_s=0.0), subsamples=1, seed=0)
    chip = bus.device(addr)
    bus.write_byte_data(addr, 0x4F, (3 << 5) | 0b0111)  # GYRO_CONFIG0: ±250 °/s, 200 Hz
    bus.write_byte_data(addr, 0x4E, 0x0F)  # low-noise
    assert chip.cutoff_hz() == 100.0 and chip._filter_rate_hz() == 800.0
    ks, xs = [], []
    while clock.monotonic() < 1.0:
        clock.sleep(1 / 200)
        hi, lo = bus.read_i2c_block_data(addr, 0x25, 2)  # GYRO_DATA_X1/X0, big-endian
        xs.append(int.from_bytes(bytes((hi, lo)), "big", signed=True) / 131.0 * DEG)
        ks.append(chip.samples_taken)
    t = chip.sample_time(np.asarray(ks))
    keep = t > 0.3
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[keep]
    gain = math.hypot(*np.linalg.lstsq(basis, np.asarray(xs)[keep], rcond=None)[0]) / amp
    # the design's response: two equal bilinear sections b (1 + z⁻¹) / (1 + a z⁻¹), together
    # −3 dB at 100 Hz at the 800 Hz they run at
    k = math.tan(math.pi * 100.0 / 800.0) / math.sqrt(math.sqrt(2.0) - 1.0)
    b, a = k / (1 + k), (k - 1) / (k + 1)
    one = np.concatenate(([b], b * (1 - a) * (-a) ** np.arange(3999)))
    h = np.convolve(one, one)[:4000]
    want = abs(np.sum(h * np.exp(-2j * np.pi * f / 800.0 * np.arange(h.size))))
    assert want == pytest.approx(0.87, abs=0.02)
    assert gain == pytest.approx(want, abs=0.01)
