"""Each emulated chip's noise and filter against its datasheet (issue 26): the white noise's
Allan deviation is the chip table's noise density (allantools as the oracle), the noise enters
ahead of the chip's filter so the noise per sample follows the filter's bandwidth, the raw
MPU-9250 applies its configured DLPF, and the filter runs on whatever the client's polling
interval."""

from __future__ import annotations

import math

import allantools
import numpy as np
import pytest

from bench.bench_chips import NOISE_SETTINGS, accel_still_stream, still_stream
from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate, FunctionMotion
from gyrocal.drivers.imu import READERS, open_imu
from gyrocal.drivers.imu.chips import MPU9250_REG

# the datasheets' rate noise spectral densities, °/s/√Hz, written out here (the LSM9DS1's is a
# stand-in: its datasheet gives none): PS-MPU-9250A-01 Table 1, DS-000189 Table 1, DS-000347
# Table 1, DS12814 Table 2
DATASHEET_DENSITY = {"mpu9250": 0.01, "lsm9ds1": 0.01, "icm20948": 0.015,
                     "icm42688p": 0.0028, "lsm6dsox": 0.0038}


def test_the_chip_table_has_each_datasheet_density():
    for model, n in DATASHEET_DENSITY.items():
        assert READERS[model].family.gyro_errors.noise_density_dps_sqrt_hz == n


@pytest.mark.parametrize("model", sorted(DATASHEET_DENSITY))
def test_white_noise_allan_deviation_is_the_datasheet_density(model):
    rate, odr, _ = still_stream(model, 5.0, seed=11)
    adev = [allantools.oadev(rate[:, j], rate=odr, data_type="freq",
                             taus=np.array([0.1]))[1][0] for j in range(3)]
    ratio = np.mean(adev) * math.sqrt(0.1) / math.radians(DATASHEET_DENSITY[model])
    assert ratio == pytest.approx(1.0, abs=0.08)  # ~3 × 45 independent 0.1 s means


# the order of each chip's filter at the settings the readers leave: the ICM-42688-P's
# GYRO_CONFIG1 resets to 0x16, GYRO_UI_FILT_ORD (bits 3:2) = 01, second order (DS-000347)
ORDER = {"mpu9250": 1, "lsm9ds1": 1, "icm20948": 1, "icm42688p": 2}


def _impulse_response(fc: float, rate: float, order: int, n: int = 4000) -> np.ndarray:
    # `order` equal bilinear first-order low-passes b (1 + z⁻¹) / (1 + a z⁻¹), prewarped so the
    # cascade is −3 dB at fc: one section's impulse response in closed form, h0 = b,
    # h_n = b (1 − a)(−a)^(n−1), convolved with itself
    k = math.tan(math.pi * fc / rate) / math.sqrt(2.0 ** (1.0 / order) - 1.0)
    b, a = k / (1 + k), (k - 1) / (k + 1)
    one = np.concatenate(([b], b * (1 - a) * (-a) ** np.arange(n - 1)))
    h = one
    for _ in range(order - 1):
        h = np.convolve(h, one)[:n]
    return h


def _filtered_sigma(density_dps: float, fc: float, rate: float, order: int = 1) -> float:
    # white noise of density N drawn at `rate` (per-sample σ = N √rate) through the cascade:
    # σ = N √(rate Σh²); for one section Σh² = 2b² / (1 + a) = k / (1 + k)
    h = _impulse_response(fc, rate, order)
    return math.radians(density_dps) * math.sqrt(rate * float(np.sum(h * h)))


def _sigma_tolerance(fc: float, rate: float, order: int, samples: int) -> float:
    # the relative standard error of σ estimated from `samples` correlated samples of noise
    # through the filter: var(s²) ≈ 2σ⁴ Σρ_k² / n (ρ the output's autocorrelation, from the
    # impulse response), so σ's relative error is √(Σρ² / 2n); 3.5 of them, plus 1 % for
    # the quantization and the stand-in
    h = _impulse_response(fc, rate, order)
    rho = np.correlate(h, h, mode="full") / np.sum(h * h)
    return 3.5 * math.sqrt(float(np.sum(rho * rho)) / (2 * samples)) + 0.01


@pytest.mark.parametrize("model", ["mpu9250", "lsm9ds1", "icm20948", "icm42688p"])
def test_noise_per_sample_follows_the_filter_bandwidth(model):
    _, _, bands, filter_rate = NOISE_SETTINGS[model]
    sigmas = []
    for band in bands:
        rate, _, fc = still_stream(model, 1.5, lowpass_hz=band, seed=5)
        assert fc == pytest.approx(band, abs=0.5)  # the reader's setting reached the chip
        sigma = float(np.mean(np.std(rate, axis=0)))
        # the streams' ODR is the filter's rate (NOISE_SETTINGS): one output per filter step
        tol = _sigma_tolerance(band, filter_rate, ORDER[model], 3 * rate.shape[0])
        assert sigma == pytest.approx(_filtered_sigma(DATASHEET_DENSITY[model], band,
                                                      filter_rate, ORDER[model]), rel=tol)
        sigmas.append(sigma)
    # narrowest against widest: smaller, not one figure for every setting (the noise used to
    # be added after the filter)
    assert sigmas[bands.index(min(bands))] / sigmas[bands.index(max(bands))] < 0.8


def _raw_mpu(motion, *, dlpf_cfg: int, seed: int = 0):
    clock = VirtualClock()
    truth = SensorTruth(noise_sigma_rad_s=0.0)
    bus, addr = make_emulated_imu("mpu9250", clock, motion, truth, seed=seed)
    chip = bus.device(addr)
    for reg, value in ((MPU9250_REG.PWR_MGMT_1, 0x01), (MPU9250_REG.CONFIG, dlpf_cfg),
                       (MPU9250_REG.SMPLRT_DIV, 0), (MPU9250_REG.GYRO_CONFIG, 0x08)):
        chip.i2c_write(bytes([reg, value]))
    return clock, chip


def _poll_x(clock, chip, dt: float, until: float) -> tuple[np.ndarray, np.ndarray]:
    ks, xs = [], []
    while clock.monotonic() < until:
        clock.sleep(dt)
        chip.i2c_write(bytes([MPU9250_REG.GYRO_XOUT_H]))
        xs.append(np.frombuffer(chip.i2c_read(2), ">i2")[0] / 65.5)
        ks.append(chip.samples_taken)
    return np.asarray(ks), np.asarray(xs)


def test_raw_mpu9250_applies_the_configured_dlpf():
    # a 100 Hz sine through DLPF_CFG 3 (41 Hz, register map CONFIG table) at 1 kHz: the
    # bilinear first-order stand-in run at the internal 1 kHz, times the sub-sample boxcar
    f, amp = 100.0, 100.0
    motion = FunctionMotion(lambda t: np.column_stack(
        [math.radians(amp) * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
    clock, chip = _raw_mpu(motion, dlpf_cfg=3)
    assert chip.cutoff_hz() == 41.0
    ks, x = _poll_x(clock, chip, 1e-3, 0.6)
    t = chip.sample_time(ks)
    keep = t > 0.2
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[keep]
    gain = math.hypot(*np.linalg.lstsq(basis, x[keep], rcond=None)[0]) / amp
    k = math.tan(math.pi * 41.0 / 1000.0)
    z = np.exp(-2j * np.pi * f / 1000.0)
    want = abs(k / (1 + k) * (1 + z) / (1 + (k - 1) / (k + 1) * z)) * np.sinc(f / 1000.0)
    assert gain == pytest.approx(want, abs=0.01)  # ≈ 0.41, not the unfiltered 0.98


def test_polling_slower_than_the_odr_keeps_the_filter_running():
    # a 100 °/s step at 0.3 s through the 41 Hz DLPF at 1 kHz: a client reading the data
    # registers every 2.6 ms sees the values a client reading every sample sees at the same
    # sample (the filter does not restart at each read)
    motion = FunctionMotion(lambda t: np.column_stack(
        [np.where(t >= 0.3, math.radians(100.0), 0.0), 0 * t, 0 * t]))
    clock, chip = _raw_mpu(motion, dlpf_cfg=3)
    every_k, every_x = _poll_x(clock, chip, 1e-3, 0.4)
    clock2, chip2 = _raw_mpu(motion, dlpf_cfg=3)
    slow_k, slow_x = _poll_x(clock2, chip2, 2.6e-3, 0.4)
    by_k = dict(zip(every_k.tolist(), every_x.tolist(), strict=True))
    both = [k for k in slow_k.tolist() if k in by_k]
    assert len(both) > 100
    got = dict(zip(slow_k.tolist(), slow_x.tolist(), strict=True))
    assert max(abs(got[k] - by_k[k]) for k in both) <= 1 / 65.5  # one count at most
    # and the step rises as the 41 Hz filter says, not at once
    t_step = chip.sample_time(np.asarray(both))
    after = np.asarray([got[k] for k in both])[(t_step > 0.3) & (t_step < 0.3026)]
    assert after.size and np.all(after < 60.0)


# DS-000189 GYRO_CONFIG_1 table, written out here: GYRO_DLPFCFG → (3 dB bandwidth, noise
# bandwidth) in Hz (SparkFun's qwiic_icm20948.py lines 107-115 carry the same figures)
ICM20948_DATASHEET_DLPF = {0: (196.6, 229.8), 3: (51.2, 73.3), 6: (5.7, 8.9)}


@pytest.mark.parametrize("band", [196.6, 51.2])
def test_icm20948_noise_per_sample_is_the_datasheet_noise_bandwidth(band):
    # white noise of two-sided density N through a filter of noise bandwidth NBW: σ = N √(2 NBW)
    # (the emulator's convention, bench.bench_chips); the first-order stand-in's noise bandwidth
    # is within 7 % of the datasheet's at 196.6 Hz, 4 % at 51.2 Hz
    nbw = dict(ICM20948_DATASHEET_DLPF.values())[band]
    rate, _, fc = still_stream("icm20948", 1.5, lowpass_hz=band, seed=7)
    assert fc == band
    sigma = float(np.mean(np.std(rate, axis=0)))
    want = math.radians(DATASHEET_DENSITY["icm20948"]) * math.sqrt(2 * nbw)
    # the statistical tolerance plus the stand-in's 3.6 % (√(213.7 / 229.8) at 196.6 Hz)
    tol = _sigma_tolerance(band, 1125.0, 1, 3 * rate.shape[0]) + 0.036
    assert sigma == pytest.approx(want, rel=tol)


def test_each_chip_table_row_is_the_datasheet_row():
    from gyrocal.drivers.imu.chips import ICM20948_GYRO_FILTER, MPU9250_GYRO_FILTER

    rows = {f.code: (f.bandwidth_hz, f.noise_bandwidth_hz) for f in ICM20948_GYRO_FILTER}
    assert all(rows[code] == row for code, row in ICM20948_DATASHEET_DLPF.items())
    # RM-MPU-9250A-00 CONFIG table: DLPF_CFG → (bandwidth Hz, delay ms)
    mpu = {1: (184, 2.9), 2: (92, 3.9), 3: (41, 5.9), 4: (20, 9.9), 5: (10, 17.85), 6: (5, 33.48)}
    assert {f.code: (f.bandwidth_hz, round(f.delay_s * 1e3, 2)) for f in MPU9250_GYRO_FILTER} == mpu


def _raw_icm42688p(motion, *, bw_code: int, order_bits: int | None, seed: int = 0,
                   truth: SensorTruth | None = None, fs_code: int = 3):
    clock = VirtualClock()
    bus, addr = make_emulated_imu("icm42688p", clock, motion,
                                  truth or SensorTruth(noise_sigma_rad_s=0.0), seed=seed)
    chip = bus.device(addr)
    bus.write_byte_data(addr, 0x52, 0x10 | bw_code)  # GYRO_ACCEL_CONFIG0.GYRO_UI_FILT_BW
    if order_bits is not None:  # GYRO_CONFIG1 with GYRO_UI_FILT_ORD in bits 3:2
        bus.write_byte_data(addr, 0x51, 0x12 | order_bits << 2)
    # GYRO_CONFIG0: 1 kHz; FS 3 ±250 °/s (131 LSB/(°/s)), 7 ±15.625 °/s (2097.2)
    bus.write_byte_data(addr, 0x4F, (fs_code << 5) | 0b0110)
    bus.write_byte_data(addr, 0x4E, 0x0F)  # gyro and accelerometer low-noise
    return clock, bus, addr, chip


def test_icm42688p_ui_filter_resets_to_second_order_and_follows_its_register():
    # DS-000347: GYRO_CONFIG1 resets to 0x16, GYRO_UI_FILT_ORD = 01 (second order); 00 first,
    # 10 third
    _, bus, addr, chip = _raw_icm42688p(ConstantRate(), bw_code=7, order_bits=None)
    assert bus.read_byte_data(addr, 0x51) == 0x16
    assert chip.filter_order() == 2
    for bits, order in ((0b00, 1), (0b01, 2), (0b10, 3)):
        bus.write_byte_data(addr, 0x51, 0x12 | bits << 2)
        assert chip.filter_order() == order


def _sine_gain(chip, clock, bus, addr, f: float) -> float:
    ks, xs = [], []
    while clock.monotonic() < 0.6:
        clock.sleep(1e-3)
        hi, lo = bus.read_i2c_block_data(addr, 0x25, 2)  # GYRO_DATA_X1/X0, big-endian
        xs.append(int.from_bytes(bytes((hi, lo)), "big", signed=True) / 131.0)
        ks.append(chip.samples_taken)
    t = chip.sample_time(np.asarray(ks))
    keep = t > 0.2
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[keep]
    return math.hypot(*np.linalg.lstsq(basis, np.asarray(xs)[keep], rcond=None)[0]) / 100.0


@pytest.mark.parametrize("order_bits,order", [(0b00, 1), (0b01, 2), (0b10, 3)])
def test_a_sine_through_the_icm42688p_ui_filter_keeps_what_its_response_says(order_bits, order):
    # GYRO_UI_FILT_BW 7 at 1 kHz: max(400, 1000)/40 = 25 Hz (DS-000347). A sine at the
    # bandwidth keeps 1/√2 whatever the order (the datasheet's −3 dB point); at 4× it keeps
    # the cascade's |H|, less the higher the order; both times the per-sample mean's sinc
    for f in (25.0, 100.0):
        motion = FunctionMotion(lambda t, f=f: np.column_stack(
            [math.radians(100.0) * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]))
        clock, bus, addr, chip = _raw_icm42688p(motion, bw_code=7, order_bits=order_bits)
        assert chip.cutoff_hz() == 25.0 and chip.filter_order() == order
        gain = _sine_gain(chip, clock, bus, addr, f)
        h = _impulse_response(25.0, 1000.0, order)
        want = abs(np.sum(h * np.exp(-2j * np.pi * f / 1000.0 * np.arange(h.size))))
        assert want * np.sinc(f / 1000.0) == pytest.approx(gain, abs=0.01)
        if f == 25.0:
            assert want == pytest.approx(1 / math.sqrt(2), abs=1e-9)
    assert gain < {1: 0.25, 2: 0.14, 3: 0.09}[order]  # 4 fc: 0.243, 0.131, 0.085 analog


def test_icm42688p_noise_per_sample_follows_bandwidth_and_order():
    # narrow setting (25 Hz at 1 kHz): σ ≈ N √(2 ENBW) with the analog prototype's noise
    # bandwidth, ENBW = f_s √π Γ(n − ½) / (2 Γ(n)), f_s = fc / √(2^(1/n) − 1) per section;
    # streamed through the reader (FIFO), the order set in GYRO_CONFIG1 after it started
    n_dps = DATASHEET_DENSITY["icm42688p"]
    for order_bits, order in ((0b00, 1), (0b01, 2)):
        clock = VirtualClock()
        bus, addr = make_emulated_imu("icm42688p", clock, seed=order)
        reader = open_imu("icm42688p", bus, addr, clock=clock, range_dps=15.625, odr_hz=1000,
                          lowpass_hz=25)
        reader.start()
        bus.write_byte_data(addr, 0x51, 0x12 | order_bits << 2)
        assert bus.device(addr).filter_order() == order
        chunks = []
        while clock.monotonic() < 3.0:
            clock.sleep(0.02)
            chunks.append(reader.read().rate)
        kept = np.vstack(chunks)[500:]
        sigma = float(np.mean(np.std(kept, axis=0)))
        fs = 25.0 / math.sqrt(2.0 ** (1.0 / order) - 1.0)
        enbw = fs * math.sqrt(math.pi) * math.gamma(order - 0.5) / (2 * math.gamma(order))
        tol = _sigma_tolerance(25.0, 1000.0, order, kept.size)
        assert sigma == pytest.approx(math.radians(n_dps) * math.sqrt(2 * enbw), rel=tol)


def test_a_cascade_runs_on_whatever_the_clients_polling():
    # a 100 °/s step at 0.3 s through the ICM-42688-P's third-order UI filter at 25 Hz: a client
    # reading the data registers every 2.6 ms sees what one reading every sample sees at the same
    # sample (every section's state carries across reads and the samples computed ahead)
    motion = FunctionMotion(lambda t: np.column_stack(
        [np.where(t >= 0.3, math.radians(100.0), 0.0), 0 * t, 0 * t]))
    seen = []
    for dt in (1e-3, 2.6e-3):
        clock, bus, addr, chip = _raw_icm42688p(motion, bw_code=7, order_bits=0b10)
        got = {}
        while clock.monotonic() < 0.45:
            clock.sleep(dt)
            hi, lo = bus.read_i2c_block_data(addr, 0x25, 2)
            got[chip.samples_taken] = int.from_bytes(bytes((hi, lo)), "big", signed=True)
        seen.append((got, chip))
    every, slow = seen[0][0], seen[1][0]
    both = sorted(set(every) & set(slow))
    assert len(both) > 100
    assert max(abs(every[k] - slow[k]) for k in both) <= 1  # one count at most
    # and the step rises as the cascade's response says, not at once: each sample's input is
    # the mean of the step over its eight sub-sample midpoints (the chip's per-sample mean),
    # convolved with the bilinear design's impulse response
    chip = seen[1][1]
    ks = np.arange(1, max(both) + 1)
    mids = chip.sample_time(ks)[:, None] + 1e-3 * ((np.arange(8) + 0.5) / 8 - 1.0)
    x = 100.0 * np.mean(mids >= 0.3, axis=1)
    want = np.convolve(x, _impulse_response(25.0, 1000.0, 3))[:ks.size] * 131.0
    got = np.asarray([slow[k] for k in both])
    assert np.max(np.abs(got - want[np.asarray(both) - 1])) <= 2  # counts: rounding, ~1e-7
    assert got[chip.sample_time(np.asarray(both)) < 0.3026].max() < 0.6 * 100 * 131


# -- the accelerometers' filters ---------------------------------------------------------------

# RM-MPU-9250A-00 ACCEL_CONFIG_2 table, written out here: A_DLPFCFG → (bandwidth Hz, delay ms);
# DS-000189 ACCEL_CONFIG table: ACCEL_DLPFCFG → (3 dB Hz, noise bandwidth Hz)
MPU9250_DATASHEET_ACCEL = {0: (218.1, 1.88), 1: (218.1, 1.88), 2: (99.0, 2.88), 3: (44.8, 4.88),
                           4: (21.2, 8.87), 5: (10.2, 16.83), 6: (5.05, 32.48), 7: (420.0, 1.38)}
ICM20948_DATASHEET_ACCEL = {0: (246.0, 265.0), 3: (50.4, 68.8), 6: (5.7, 8.3), 7: (473.0, 499.0)}


def test_each_accel_filter_table_row_is_the_datasheet_row():
    from gyrocal.drivers.imu.chips import ICM20948_ACCEL_FILTER, MPU9250_ACCEL_FILTER

    assert {f.code: (f.bandwidth_hz, round(f.delay_s * 1e3, 2))
            for f in MPU9250_ACCEL_FILTER} == MPU9250_DATASHEET_ACCEL
    rows = {f.code: (f.bandwidth_hz, f.noise_bandwidth_hz) for f in ICM20948_ACCEL_FILTER}
    assert all(rows[code] == row for code, row in ICM20948_DATASHEET_ACCEL.items())


@pytest.mark.parametrize("a_dlpfcfg,odr", [(0, 1000.0), (0, 200.0), (3, 1000.0)])
def test_mpu9250_accel_noise_enters_ahead_of_its_dlpf(a_dlpfcfg, odr):
    # ACCEL_CONFIG_2 A_DLPFCFG (reset 0: 218.1 Hz) at the internal 1 kHz, whatever SMPLRT_DIV:
    # σ = N √(1000 Σh²) at 1 kHz and at 200 Hz alike (it used to be N √odr), smaller at 44.8 Hz
    a, n_m_s2, chip = accel_still_stream("mpu9250", 2.0, odr, [(0x1D, a_dlpfcfg)])
    bandwidth = MPU9250_DATASHEET_ACCEL[a_dlpfcfg][0]
    assert chip.accel_filter_setting().bandwidth_hz == bandwidth
    sigma = float(np.mean(np.std(a, axis=0)))
    want = _filtered_sigma(math.degrees(n_m_s2), bandwidth, 1000.0)
    assert sigma == pytest.approx(want, rel=_sigma_tolerance(bandwidth, 1000.0, 1, a.size * 5))


def test_icm20948_accel_noise_is_the_datasheet_noise_bandwidth():
    # reset ACCEL_CONFIG (ACCEL_FCHOICE = 1, ACCEL_DLPFCFG 0): 246 Hz, NBW 265 Hz at 1125 Hz;
    # σ = N √(2 NBW) in the emulator's convention, the first-order stand-in's within 2 %
    a, n_m_s2, chip = accel_still_stream("icm20948", 2.0, 1125.0)
    assert chip.accel_filter_setting().noise_bandwidth_hz == 265.0
    sigma = float(np.mean(np.std(a, axis=0)))
    tol = _sigma_tolerance(246.0, 1125.0, 1, a.size) + 0.02
    assert sigma == pytest.approx(n_m_s2 * math.sqrt(2 * 265.0), rel=tol)


def test_icm42688p_accel_ui_filter_is_second_order_at_reset():
    # DS-000347: ACCEL_CONFIG1 resets to 0x0D (ACCEL_UI_FILT_ORD = 01), GYRO_ACCEL_CONFIG0 to
    # 0x11 (ACCEL_UI_FILT_BW 1: max(400, 1000)/4 = 250 Hz at 1 kHz)
    a, n_m_s2, chip = accel_still_stream("icm42688p", 2.0, 1000.0)
    assert chip.accel_filter_order() == 2 and chip.accel_filter_setting().bandwidth_hz == 250.0
    sigma = float(np.mean(np.std(a, axis=0)))
    want = _filtered_sigma(math.degrees(n_m_s2), 250.0, 1000.0, 2)
    assert sigma == pytest.approx(want, rel=_sigma_tolerance(250.0, 1000.0, 2, a.size))


def test_the_accel_filter_runs_on_whatever_the_clients_polling():
    # the MPU-9250's 5.05 Hz accelerometer DLPF (A_DLPFCFG 6) with its noise: ACCEL_XOUT read
    # every 1 ms and every 2.6 ms give the same counts at the same samples
    from gyrocal.drivers.emulated.accel import AccelTruth

    seen = []
    for dt in (1e-3, 2.6e-3):
        clock = VirtualClock()
        truth = SensorTruth(noise_sigma_rad_s=0.0,
                            accelerometer=AccelTruth(noise_density_g_sqrt_hz=300e-6))
        bus, addr = make_emulated_imu("mpu9250", clock, truth=truth, seed=4)
        chip = bus.device(addr)
        for reg, value in ((MPU9250_REG.PWR_MGMT_1, 0x01), (MPU9250_REG.CONFIG, 3),
                           (MPU9250_REG.SMPLRT_DIV, 0), (0x1D, 6)):
            chip.i2c_write(bytes([reg, value]))
        got = {}
        while clock.monotonic() < 0.4:
            clock.sleep(dt)
            chip.i2c_write(bytes([0x3B]))  # ACCEL_XOUT_H
            got[chip.samples_taken] = int(np.frombuffer(chip.i2c_read(2), ">i2")[0])
        seen.append(got)
    both = sorted(set(seen[0]) & set(seen[1]))
    assert len(both) > 100
    assert max(abs(seen[0][k] - seen[1][k]) for k in both) <= 1
    # and the filter narrows the noise: 300 µg/√Hz through 5.05 Hz, ≈ N √(π fc) = 1.2 mg,
    # about 20 counts at ±2 g, not the unfiltered N √1000 ≈ 9.5 mg
    x = np.asarray([seen[1][k] for k in both if k > 150]) / 16384.0
    assert 0.5e-3 < np.std(x) < 2.5e-3


class _ShakenStill:
    """At rest, its specific force 1 g on z plus an x-axis sine of ``amp_g`` at ``f`` Hz."""

    def __init__(self, f: float, amp_g: float) -> None:
        self.f, self.amp_g = f, amp_g

    def rate(self, t):
        return np.zeros((np.size(t), 3))

    def specific_force(self, t, peek: bool = False):
        t = np.asarray(t, dtype=float)
        return np.column_stack([self.amp_g * np.sin(2 * np.pi * self.f * t), 0 * t, 1 + 0 * t])


@pytest.mark.parametrize("f", [44.8, 120.0])
def test_a_sine_through_the_mpu9250_accel_dlpf_keeps_what_its_response_says(f):
    # A_DLPFCFG 3 (44.8 Hz, register map ACCEL_CONFIG_2) at 1 kHz, an ideal accelerometer
    # shown the motion's specific force: a sine at the bandwidth keeps 1/√2 (the datasheet's
    # −3 dB point), one at 120 Hz the first-order bilinear design's |H|
    from gyrocal.drivers.emulated.imu_chips import SensorRealism

    clock = VirtualClock()
    truth = SensorTruth(noise_sigma_rad_s=0.0, realism=SensorRealism(specific_force=True))
    bus, addr = make_emulated_imu("mpu9250", clock, _ShakenStill(f, 0.5), truth)
    chip = bus.device(addr)
    for reg, value in ((MPU9250_REG.PWR_MGMT_1, 0x01), (MPU9250_REG.CONFIG, 3),
                       (MPU9250_REG.SMPLRT_DIV, 0), (0x1D, 3)):
        chip.i2c_write(bytes([reg, value]))
    ks, xs = [], []
    while clock.monotonic() < 0.6:
        clock.sleep(1e-3)
        chip.i2c_write(bytes([0x3B]))  # ACCEL_XOUT_H, ±2 g: 16384 LSB/g
        xs.append(np.frombuffer(chip.i2c_read(2), ">i2")[0] / 16384.0)
        ks.append(chip.samples_taken)
    t = chip.sample_time(np.asarray(ks)) - chip._pure_delay_s(1e-3)  # the force's times
    keep = t > 0.2
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])[keep]
    gain = math.hypot(*np.linalg.lstsq(basis, np.asarray(xs)[keep], rcond=None)[0]) / 0.5
    h = _impulse_response(44.8, 1000.0, 1)
    want = abs(np.sum(h * np.exp(-2j * np.pi * f / 1000.0 * np.arange(h.size))))
    assert gain == pytest.approx(want, abs=0.005)
    if f == 44.8:
        assert want == pytest.approx(1 / math.sqrt(2), abs=1e-9)
