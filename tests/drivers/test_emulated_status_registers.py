"""Data-ready and status bits, offset and self-test registers, reset values of the emulated
chips, each against its datasheet (register addresses and formulas written out here).

Sources: MPU-9250 register map RM-MPU-9250A-00 (SELF_TEST 0x00-0x02/0x0D-0x0F, XG_OFFSET_H..
ZG_OFFSET_L 0x13-0x18 "OffsetLSB = X_OFFS_USR * 4 / 2^FS_SEL", INT_PIN_CFG 0x37 bit 4
INT_ANYRD_2CLEAR, INT_STATUS 0x3A bit 0 RAW_DATA_RDY_INT) and the self-test application note
AN-MPU-9250A-03 (factory trim 2620/2^FS * 1.01^(code-1); pass: gyro STR/FT > 0.5, accel
0.5 < STR/FT < 1.5); ICM-20948 DS-000189 (INT_STATUS_1 0x1A, bank 2 XG_OFFS_USRH 0x03,
ACCEL_CONFIG 0x14 reset 0x01; bank 1 SELF_TEST codes, bank 2 GYRO_CONFIG_2/ACCEL_CONFIG_2 self-test
enables, through TDK's own self-test code, cited where it is modelled); ICM-42688-P DS-000347
(INT_STATUS 0x2D: DATA_RDY bit 3, RESET_DONE bit 4; the bank-0 reset values of its §14, those of
banks 1, 2 and 4 from §15 on); LSM6DSOX DS12814
(STATUS_REG 0x1E: XLDA bit 0, GDA bit 1, TDA bit 2).
"""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import ConstantRate

DEG = math.pi / 180
OMEGA = np.array([10.0, -20.0, 30.0]) * DEG


def chip(model, truth=None, omega=OMEGA):
    clock = VirtualClock()
    truth = truth or SensorTruth(noise_density_rad_s_sqrt_hz=0.0)
    bus, addr = make_emulated_imu(model, clock, ConstantRate(omega), truth, subsamples=1)
    return clock, bus, addr, truth


def be16s(data):
    return np.frombuffer(bytes(data), dtype=">i2").astype(int)


# -- MPU-9250 ----------------------------------------------------------------------------------


def mpu_awake(bus, addr, fs=0):
    bus.write_byte_data(addr, 0x6B, 0x01)  # PWR_MGMT_1: awake
    bus.write_byte_data(addr, 0x1A, 0x01)  # CONFIG: DLPF_CFG 1, 1 kHz
    bus.write_byte_data(addr, 0x1B, fs << 3)  # GYRO_CONFIG


def mpu_gyro(bus, addr):
    return be16s(bus.read_i2c_block_data(addr, 0x43, 6))


@pytest.mark.parametrize("fs", [0, 1, 3])
def test_mpu9250_offset_registers_add_x_offs_usr_times_4_over_2_to_fs(fs):
    clock, bus, addr, truth = chip("mpu9250")
    mpu_awake(bus, addr, fs)
    clock.sleep(0.01)
    lsb_per_dps = (131.0, 65.5, 32.8, 16.4)[fs]
    base = np.rint(truth.reading(OMEGA[None], np.array([25.0]))[0] / DEG * lsb_per_dps)
    np.testing.assert_array_equal(mpu_gyro(bus, addr), base)
    codes = (400, -1000, 7)
    bus.write_i2c_block_data(addr, 0x13, list(np.array(codes, ">i2").tobytes()))
    clock.sleep(0.01)
    np.testing.assert_allclose(mpu_gyro(bus, addr), base + np.array(codes) * 4 / 2**fs, atol=0.5)


def test_mpu9250_self_test_passes_the_application_note_procedure():
    # Kris Winer's MPU9250SelfTest / AN-MPU-9250A-03, with 20 samples instead of 200
    clock, bus, addr, _ = chip("mpu9250")
    w = bus.write_byte_data
    mpu_awake(bus, addr, 0)
    w(addr, 0x1A, 0x02)  # DLPF 92 Hz
    w(addr, 0x1D, 0x02)
    w(addr, 0x1C, 0x00)  # ±2 g

    def average():
        a, g = np.zeros(3), np.zeros(3)
        for _ in range(20):
            clock.sleep(0.001)
            d = be16s(bus.read_i2c_block_data(addr, 0x3B, 14))
            a, g = a + d[:3], g + d[4:]
        return a / 20, g / 20

    clock.sleep(0.05)
    a0, g0 = average()
    w(addr, 0x1B, 0xE0)  # XGYRO_Cten | YGYRO_Cten | ZGYRO_Cten, ±250 °/s
    w(addr, 0x1C, 0xE0)  # ax/ay/az_st_en, ±2 g
    clock.sleep(0.025)
    a1, g1 = average()
    codes = bus.read_i2c_block_data(addr, 0x00, 3) + bus.read_i2c_block_data(addr, 0x0D, 3)
    assert all(0 < c < 256 for c in codes)
    trim = 2620.0 * 1.01 ** (np.array(codes, dtype=float) - 1)  # FS = 0
    assert np.all((g1 - g0) / trim[:3] > 0.5)
    assert np.all(np.abs((a1 - a0) / trim[3:] - 1) < 0.5)
    w(addr, 0x1B, 0x00)
    w(addr, 0x1C, 0x00)
    clock.sleep(0.025)
    np.testing.assert_allclose(average()[1], g0, atol=0.5)  # self-test off: back where it was


def test_mpu9250_raw_data_ready_set_on_new_data_cleared_by_reading_int_status():
    clock, bus, addr, _ = chip("mpu9250")
    mpu_awake(bus, addr)
    clock.sleep(0.005)
    assert bus.read_byte_data(addr, 0x3A) & 0x01
    assert bus.read_byte_data(addr, 0x3A) & 0x01 == 0  # cleared by that read
    clock.sleep(0.005)
    mpu_gyro(bus, addr)  # a data read alone does not clear it (INT_ANYRD_2CLEAR = 0)
    assert bus.read_byte_data(addr, 0x3A) & 0x01
    bus.write_byte_data(addr, 0x37, 0x10)  # INT_ANYRD_2CLEAR: any read clears it
    clock.sleep(0.005)
    mpu_gyro(bus, addr)
    assert bus.read_byte_data(addr, 0x3A) & 0x01 == 0


# -- ICM-20948 ---------------------------------------------------------------------------------


def icm_awake(bus, addr):
    bus.write_byte_data(addr, 0x06, 0x01)  # PWR_MGMT_1: awake
    bus.write_byte_data(addr, 0x7F, 0x20)  # bank 2
    bus.write_byte_data(addr, 0x01, 0x03)  # GYRO_CONFIG_1: ±500 °/s, DLPF on
    bus.write_byte_data(addr, 0x00, 10)  # GYRO_SMPLRT_DIV: 1125 / 11 Hz


def test_icm20948_int_status_1_and_reset_values():
    clock, bus, addr, truth = chip("icm20948")
    bus.write_byte_data(addr, 0x7F, 0x20)
    assert bus.read_byte_data(addr, 0x14) == 0x01  # ACCEL_CONFIG: ACCEL_FCHOICE
    bus.write_byte_data(addr, 0x7F, 0x00)
    assert bus.read_byte_data(addr, 0x05) == 0x40  # LP_CONFIG: I2C_MST_CYCLE
    assert bus.read_byte_data(addr, 0x1A) == 0  # asleep: no data yet
    icm_awake(bus, addr)
    bus.write_byte_data(addr, 0x7F, 0x00)
    clock.sleep(0.015)
    assert bus.read_byte_data(addr, 0x1A) == 0x01  # RAW_DATA_0_RDY_INT
    assert bus.read_byte_data(addr, 0x1A) == 0x00  # R/C


def test_icm20948_gyro_offset_registers_act_on_the_output():
    clock, bus, addr, truth = chip("icm20948")
    icm_awake(bus, addr)
    codes = (-300, 120, 0)
    bus.write_i2c_block_data(addr, 0x03, list(np.array(codes, ">i2").tobytes()))
    bus.write_byte_data(addr, 0x7F, 0x00)
    clock.sleep(0.01)
    base = np.rint(truth.reading(OMEGA[None], np.array([25.0]))[0] / DEG * 65.5)
    got = be16s(bus.read_i2c_block_data(addr, 0x33, 6))
    np.testing.assert_allclose(got, base + np.array(codes) * 4 / 2, atol=0.5)  # FS_SEL 1


# -- TDK's own ICM-20948 self-test, modelled from its source ---------------------------------
#
# TDK InvenSense eMD-SmartMotion-ICM20948-1.1.0 as vendored by FredBill1/RT1064_Smartcar (commit
# e3bff2e4), Libraries/eMD-SmartMotion-ICM20948-1.1.0-MP/Invn/Devices/Drivers/ICM20948/:
# Icm20948SelfTest.c (line numbers below are this file's) and Icm20948Defs.h (addresses: bank 1
# REG_SELF_TEST1..6 0x02-0x04, 0x0E-0x10 at 185-190; bank 2 GYRO_CONFIG_1 0x01, GYRO_CONFIG_2
# 0x02 with BIT_GYRO_CTEN 0x38, ACCEL_CONFIG 0x14, ACCEL_CONFIG_2 0x15 with BIT_ACCEL_CTEN
# 0x1C at 202-223; bank 0 PWR_MGMT_1 0x06, PWR_MGMT_2 0x07, LP_CONFIG 0x05, ACCEL_XOUT_H 0x2D,
# GYRO_XOUT_H 0x33; GYRO_ENGINE_UP_TIME 50 ms at 283). Registers are written bank by bank
# through REG_BANK_SEL 0x7F (USER_BANK in bits 5:4), as inv_icm20948_write_single_mems_reg
# does for an address BANK_n | reg.

EMD_SAMPLES = 200  # DEF_ST_SAMPLES, line 37


def emd_write(bus, addr, bank, register, value):
    bus.write_byte_data(addr, 0x7F, bank << 4)
    bus.write_byte_data(addr, register, value)


def emd_setup(bus, addr, clock):
    """inv_setup_selftest, lines 254-320: the factory codes (gyro, accel) it reads."""
    emd_write(bus, addr, 0, 0x06, 0x01)  # 266: PWR_MGMT_1 = BIT_CLK_PLL
    emd_write(bus, addr, 0, 0x07, 0x38 | 0x07)  # 269: accel and gyro standby
    emd_write(bus, addr, 0, 0x06, 0x80)  # 274: BIT_H_RESET
    clock.sleep(0.100)  # 275
    emd_write(bus, addr, 0, 0x06, 0x01)  # 278
    emd_write(bus, addr, 0, 0x05, 0x40 | 0x20 | 0x10)  # 283: LP_CONFIG, the three cycle bits
    emd_write(bus, addr, 2, 0x00, 10)  # 287: GYRO_SMPLRT_DIV = SELFTEST_GYRO_SMPLRT_DIV
    emd_write(bus, addr, 2, 0x01, (0 << 3) | 1)  # 289: GYRO_CONFIG_1 = SELFTEST_GYRO_FS
    emd_write(bus, addr, 2, 0x02, 3)  # 291: GYRO_CONFIG_2 = SELFTEST_GYRO_AVGCFG
    emd_write(bus, addr, 2, 0x10, 0)  # 294: ACCEL_SMPLRT_DIV_1
    emd_write(bus, addr, 2, 0x11, 10)  # 296: ACCEL_SMPLRT_DIV_2
    emd_write(bus, addr, 2, 0x14, (7 << 3) | 1)  # 298: ACCEL_CONFIG = SELFTEST_ACCEL_FS
    emd_write(bus, addr, 2, 0x15, 2)  # 300: ACCEL_CONFIG_2 = SELFTEST_ACCEL_DEC3_CFG
    bus.write_byte_data(addr, 0x7F, 1 << 4)  # 304-314: REG_SELF_TEST1..6, bank 1
    gyro_codes = [bus.read_byte_data(addr, r) for r in (0x02, 0x03, 0x04)]
    accel_codes = [bus.read_byte_data(addr, r) for r in (0x0E, 0x0F, 0x10)]
    clock.sleep(0.050)  # 317: GYRO_ENGINE_UP_TIME
    return gyro_codes, accel_codes


def emd_mean(bus, addr, clock, register):
    """inv_selftest_read_samples (322-359) and the division after it (380, 405): 200 reads of
    X/Y/Z as int16, 10 ms apart, summed, divided in C's int arithmetic (toward zero)."""
    bus.write_byte_data(addr, 0x7F, 0x00)
    total = np.zeros(3, dtype=np.int64)
    for _ in range(EMD_SAMPLES):
        total += be16s(bus.read_i2c_block_data(addr, register, 6))
        clock.sleep(0.010)  # 354: WAIT_TIME_BTW_2_SAMPLESREAD
    return np.trunc(total / EMD_SAMPLES).astype(int)


def emd_test(bus, addr, clock, gyro):
    """inv_do_test_accelgyro, lines 362-409: the means without and with the self-test on."""
    normal = emd_mean(bus, addr, clock, 0x33 if gyro else 0x2D)
    if gyro:
        emd_write(bus, addr, 2, 0x02, 0x38 | 3)  # 387: BIT_GYRO_CTEN | SELFTEST_GYRO_AVGCFG
    else:
        emd_write(bus, addr, 2, 0x15, 0x1C | 2)  # 390: BIT_ACCEL_CTEN | DEC3_CFG
    clock.sleep(0.020)  # 396: DEF_ST_STABLE_TIME
    return normal, emd_mean(bus, addr, clock, 0x33 if gyro else 0x2D)


def emd_check(codes, normal, st, gyro):
    """inv_check_accelgyro_self_test, lines 204-252: True when the sensor passes."""
    if 0 in codes:
        return False  # 218-223: a code of 0 fails
    # 219, sSelfTestEquation (70-103): 2620 * 1.01^(code - 1), truncated to uint16 (the table
    # holds exactly these for codes 1..255)
    otp = np.array([int(2620 * 1.01 ** (c - 1)) for c in codes])
    diff = st - normal  # 234
    low = np.all(diff >= otp >> 1)  # 241: fails below LOWER_BOUND_CHECK, value >> 1
    high = gyro or np.all(diff <= otp + (otp >> 1))  # 245: above UPPER_BOUND_CHECK (accel)
    return bool(low and high)


def emd_run_selftest(bus, addr, clock):
    """inv_icm20948_run_selftest, lines 411-463, less the compass: (accel << 1) | gyro."""
    gyro_codes, accel_codes = emd_setup(bus, addr, clock)
    gyro = emd_check(gyro_codes, *emd_test(bus, addr, clock, True), True)  # 428-437, 454
    accel = emd_check(accel_codes, *emd_test(bus, addr, clock, False), False)  # 440-449, 453
    return (accel << 1) | gyro  # 461-463


@pytest.mark.parametrize("response", [True, False], ids=["with-response", "response-removed"])
def test_icm20948_passes_tdks_own_self_test_and_fails_without_its_response(
        response, monkeypatch):
    if not response:  # the codes stay, the actuation they stand for is gone
        monkeypatch.setattr("gyrocal.drivers.emulated.icm20948.self_test_counts",
                            lambda *args: 0.0)
    clock = VirtualClock()
    truth = SensorTruth(bias=np.array([0.5, -1.0, 2.0]) * DEG)  # the datasheet noise density
    bus, addr = make_emulated_imu("icm20948", clock, truth=truth, seed=7)
    assert emd_run_selftest(bus, addr, clock) == (0b11 if response else 0b00)


# -- TDK's own ICM-42688-P self-test, modelled from its source --------------------------------
#
# TDK InvenSense eMD for the ICM-426xx family (the ICM-42688-P is one of its
# CONFIG_ICM426XX_DEV_NAME choices, Icm426xxDefs.h:56-57) as vendored by
# VaderMester/ESP32-ICM426XX-driver (commit 9465655d), components/ICM426XX/Invn/Drivers/Icm426xx/:
# Icm426xxSelfTest.c (line numbers below are this file's) and Icm426xxDefs.h (bank 0
# ACCEL_DATA_X0_UI 0x1F, GYRO_DATA_X0_UI 0x25, INT_STATUS 0x2D at 138-142, INTF_CONFIG0 0x4C ..
# ACCEL_CONFIG1 0x53 at 157-164, SELF_TEST_CONFIG 0x70 at 180, REG_BANK_SEL 0x76 at 186; bank 1
# XG_ST_DATA 0x5F at 194, bank 2 XA_ST_DATA 0x3B at 208; BIT_INT_STATUS_DRDY 0x08 at 475;
# SELF_TEST_CONFIG bits at 1345-1351; GYRO_MODE bits 3:2 and ACCEL_MODE bits 1:0, LN = 11, at
# 747-764; FS_SEL bits 7:5, 250 dps = 3 and 4 g = 2, at 773, 794, 830, 845; ODR 1 kHz = 6 at 815
# and 868; UI filter third order = 2 at bits 3:2 / 4:3, 893, 957; bandwidth ODR/10 = 4 at 915,
# 937). The data's byte order is INTF_CONFIG0 bit 4, read at the driver's set-up
# (Icm426xxDriver_HL.c:134-135).

TDK426_SAMPLES = 200  # average_sensor_output, line 459


def tdk426_rmw(bus, addr, register, clear, value):
    """The read-modify-write of one register every step below uses."""
    old = bus.read_byte_data(addr, register)
    bus.write_byte_data(addr, register, (old & ~clear & 0xFF) | value)


def tdk426_average(bus, addr, clock, gyro, st_bits):
    """average_sensor_output, lines 376-482: the sensor on in low-noise mode, the self-test bits
    (if any) on, 200 data-ready samples averaged in C's int arithmetic, then both off."""
    big = bool(bus.read_byte_data(addr, 0x4C) & 0x10)  # s->endianess_data
    data_reg = 0x25 if gyro else 0x1F  # 388, 400
    mode = 0x0C if gyro else 0x03
    tdk426_rmw(bus, addr, 0x4E, mode, mode)  # 391-394, 403-406: GYRO_MODE / ACCEL_MODE LN
    clock.sleep(0.060 if gyro else 0.025)  # 397, 409
    if st_bits:
        st = bus.read_byte_data(addr, 0x70) | st_bits  # 416-418
        bus.write_byte_data(addr, 0x70, st)
        clock.sleep(0.200 if gyro else 0.025)  # 422, 425
    total, it, discarded, timeout = [0, 0, 0], 0, 0, 300
    while True:  # 428-459: do { ... } while ((it < 200) && (timeout > 0))
        if bus.read_byte_data(addr, 0x2D) & 0x08:  # 430-432
            raw = bytes(bus.read_i2c_block_data(addr, data_reg, 6))  # 437
            d = [int(v) for v in np.frombuffer(raw, dtype=">i2" if big else "<i2")]  # 439-447
            if -32768 not in d:  # 448-454
                total = [s + v for s, v in zip(total, d, strict=True)]
            else:
                discarded += 1
            it += 1
        clock.sleep(0.001)  # 457
        timeout -= 1
        if not (it < TDK426_SAMPLES and timeout > 0):
            break
    tdk426_rmw(bus, addr, 0x4E, 0x0F, 0x00)  # 462-467: gyro and accelerometer off
    if st_bits:
        bus.write_byte_data(addr, 0x70, st & ~st_bits)  # 470-473
    n = it - discarded  # 476; no sample at all divides by zero (in C too)
    return [int(s / n) for s in total]  # 477-479: int32 / int, toward zero


def tdk426_otp(fs_sel, code):
    """INV_ST_OTP_EQUATION (line 62), cast to uint32_t: a code of 0 is not special here."""
    return int(2620 / 2 ** (3 - fs_sel) * 1.01 ** (code - 1) + 0.5)


def tdk426_codes(bus, addr, bank, register):
    bus.write_byte_data(addr, 0x76, bank)  # 239-243, 329-333
    codes = bus.read_i2c_block_data(addr, register, 3)
    bus.write_byte_data(addr, 0x76, 0)
    return codes


def tdk426_gyro(bus, addr, clock):
    """run_gyro_self_test, lines 190-271: 1 when the gyro passes."""
    tdk426_rmw(bus, addr, 0x4F, 0xE0 | 0x0F, (3 << 5) | 0x06)  # 209-214: ±250 °/s, 1 kHz
    tdk426_rmw(bus, addr, 0x51, 0x0C, 2 << 2)  # 216-219: UI filter third order
    tdk426_rmw(bus, addr, 0x52, 0x0F, 0x04)  # 221-224: bandwidth ODR/10
    off = tdk426_average(bus, addr, clock, True, 0)  # 227
    on = tdk426_average(bus, addr, clock, True, 0x01 | 0x02 | 0x04)  # 231-232
    response = [abs(a - b) for a, b in zip(on, off, strict=True)]  # 235-236
    otp = [tdk426_otp(3, c) for c in tdk426_codes(bus, addr, 1, 0x5F)]  # 239-248
    sensitivity = 32768 // 250  # 251
    result = 1
    for r, o in zip(response, otp, strict=True):  # 253-261
        if o and r / o <= 0.5:  # MIN_RATIO_GYRO, line 66
            result = 0
        elif not o and r < 60 * sensitivity:  # MIN_ST_GYRO_DPS, line 67
            result = 0
    if any(abs(v) > 20 * sensitivity for v in off):  # 264-266: MAX_ST_GYRO_OFFSET_DPS
        result = 0
    return result


def tdk426_accel(bus, addr, clock):
    """run_accel_self_test, lines 278-374: 1 when the accelerometer passes."""
    tdk426_rmw(bus, addr, 0x50, 0xE0 | 0x0F, (2 << 5) | 0x06)  # 298-303: ±4 g, 1 kHz
    tdk426_rmw(bus, addr, 0x53, 0x18, 2 << 3)  # 305-308: UI filter third order
    tdk426_rmw(bus, addr, 0x52, 0xF0, 0x04 << 4)  # 310-313: bandwidth ODR/10
    off = tdk426_average(bus, addr, clock, False, 0)  # 316
    on = tdk426_average(bus, addr, clock, False, 0x08 | 0x10 | 0x20 | 0x40)  # 320-321
    response = [abs(a - b) for a, b in zip(on, off, strict=True)]  # 325-326
    otp = [tdk426_otp(2, c) for c in tdk426_codes(bus, addr, 2, 0x3B)]  # 329-338
    sensitivity = 32768 // 4  # 342
    result = 1
    for r, o in zip(response, otp, strict=True):  # 344-353
        if o and not 0.5 < r / o < 1.5:  # MIN/MAX_RATIO_GYRO, lines 70-71
            result = 0
        elif not o and not 50 * sensitivity // 1000 <= r <= 1200 * sensitivity // 1000:
            result = 0  # MIN/MAX_ST_ACCEL_MG, lines 72-73
    return result


def tdk426_run_selftest(bus, addr, clock):
    """inv_icm426xx_run_selftest, lines 109-140: (accel << 1) | gyro. Not modelled: saving and
    restoring the settings (121, 132) and writing the biases found to bank 4's user offsets
    (124-129); the result depends on neither."""
    gyro = tdk426_gyro(bus, addr, clock)  # 123
    accel = tdk426_accel(bus, addr, clock)  # 127
    return (accel << 1) | gyro  # 135


@pytest.mark.parametrize("response", [True, False], ids=["with-response", "response-removed"])
def test_icm42688p_passes_tdks_own_self_test_and_fails_without_its_response(
        response, monkeypatch):
    if not response:  # the codes stay, the actuation they stand for is gone
        monkeypatch.setattr("gyrocal.drivers.emulated.icm42688p.self_test_counts",
                            lambda *args: 0.0)
    clock = VirtualClock()
    truth = SensorTruth(bias=np.array([0.5, -1.0, 2.0]) * DEG)  # the datasheet noise density
    bus, addr = make_emulated_imu("icm42688p", clock, truth=truth, seed=7, subsamples=1)
    assert tdk426_run_selftest(bus, addr, clock) == (0b11 if response else 0b00)


@pytest.mark.parametrize(("gyro_fs", "accel_fs"), [(0, 0), (3, 2), (4, 3)])
def test_icm42688p_self_test_bits_move_each_axis_by_its_codes_response(gyro_fs, accel_fs):
    # TDK's INV_ST_OTP_EQUATION at each range (FS_SEL 000 = ±2000 °/s / ±16 g, 100 = ±125 °/s):
    # one axis at a time, the others unmoved; at rest, so ±125 °/s holds the response
    clock, bus, addr, _ = chip("icm42688p", omega=np.zeros(3))
    bus.write_byte_data(addr, 0x4F, (gyro_fs << 5) | 0x06)  # GYRO_CONFIG0, 1 kHz
    bus.write_byte_data(addr, 0x50, (accel_fs << 5) | 0x06)  # ACCEL_CONFIG0, 1 kHz
    bus.write_byte_data(addr, 0x4E, 0x0F)
    gyro_codes = tdk426_codes(bus, addr, 1, 0x5F)
    accel_codes = tdk426_codes(bus, addr, 2, 0x3B)

    def accel_gyro():
        clock.sleep(0.1)  # the UI filter settles
        return be16s(bus.read_i2c_block_data(addr, 0x1F, 12))

    base = accel_gyro()
    for axis in range(3):
        bus.write_byte_data(addr, 0x70, (0x01 << axis) | (0x08 << axis))
        moved = accel_gyro() - base
        expected = np.zeros(6)
        expected[axis] = 2620 / 2 ** (3 - accel_fs) * 1.01 ** (accel_codes[axis] - 1)
        expected[3 + axis] = 2620 / 2 ** (3 - gyro_fs) * 1.01 ** (gyro_codes[axis] - 1)
        np.testing.assert_allclose(moved, expected, atol=1.0)
    bus.write_byte_data(addr, 0x70, 0x00)
    np.testing.assert_array_equal(accel_gyro(), base)


def test_icm42688p_gyro_off_accelerometer_alone_samples_gyro_data_invalid():
    clock, bus, addr, _ = chip("icm42688p")
    bus.write_byte_data(addr, 0x50, 0x46)  # ACCEL_CONFIG0: ±4 g, 1 kHz
    bus.write_byte_data(addr, 0x4E, 0x03)  # PWR_MGMT0: the accelerometer alone, low-noise
    clock.sleep(0.01)
    assert bus.read_byte_data(addr, 0x2D) & 0x08  # DATA_RDY_INT
    data = be16s(bus.read_i2c_block_data(addr, 0x1F, 12))
    assert -32768 not in data[:3] and abs(np.linalg.norm(data[:3]) / 8192 - 1) < 0.05  # 1 g
    np.testing.assert_array_equal(data[3:], [-32768] * 3)


# -- ICM-42688-P, LSM6DSOX ---------------------------------------------------------------------


#: DS-000347 Rev 1.8 §14 bank-0 reset values (register descriptions 14.1-14.59): DEVICE_CONFIG,
#: DRIVE_CONFIG, INT_CONFIG, FIFO_CONFIG, INTF_CONFIG0, INTF_CONFIG1, PWR_MGMT0, GYRO_CONFIG0,
#: ACCEL_CONFIG0, GYRO_CONFIG1, GYRO_ACCEL_CONFIG0, ACCEL_CONFIG1, TMST_CONFIG, APEX_CONFIG0,
#: FIFO_CONFIG1, FSYNC_CONFIG, INT_CONFIG0, INT_CONFIG1, INT_SOURCE0, WHO_AM_I, REG_BANK_SEL
ICM42688P_BANK0_RESET = (
    (0x11, 0x00), (0x13, 0x05), (0x14, 0x00), (0x16, 0x00), (0x4C, 0x30), (0x4D, 0x91),
    (0x4E, 0x00), (0x4F, 0x06), (0x50, 0x06), (0x51, 0x16), (0x52, 0x11), (0x53, 0x0D),
    (0x54, 0x23), (0x56, 0x82), (0x5F, 0x00), (0x62, 0x10), (0x63, 0x00), (0x64, 0x10),
    (0x65, 0x10), (0x75, 0x47), (0x76, 0x00),
)


def test_icm42688p_reset_values_and_reset_done():
    clock, bus, addr, _ = chip("icm42688p")
    for register, value in ICM42688P_BANK0_RESET:
        assert bus.read_byte_data(addr, register) == value, hex(register)
    assert bus.read_byte_data(addr, 0x30) == 0xFF  # FIFO_DATA: the FIFO is empty
    # the sensor data registers read 0x8000 until the first sample
    assert bus.read_i2c_block_data(addr, 0x1D, 14) == [0x80, 0x00] * 7
    assert bus.read_byte_data(addr, 0x2D) & 0x10  # RESET_DONE_INT after power-on
    assert bus.read_byte_data(addr, 0x2D) & 0x10 == 0  # cleared when read
    for register in (0x4C, 0x4D, 0x51, 0x52, 0x53, 0x54, 0x56, 0x62, 0x64, 0x65):
        bus.write_byte_data(addr, register, 0x00)  # ... then a soft reset restores them all
    bus.write_byte_data(addr, 0x11, 0x01)  # DEVICE_CONFIG.SOFT_RESET
    for register, value in ICM42688P_BANK0_RESET:
        assert bus.read_byte_data(addr, register) == value, hex(register)
    assert bus.read_byte_data(addr, 0x2D) & 0x10
    bus.write_byte_data(addr, 0x4E, 0x0F)  # PWR_MGMT0: gyro and accel low-noise
    clock.sleep(0.01)
    assert bus.read_byte_data(addr, 0x2D) & 0x08  # DATA_RDY_INT
    assert bus.read_byte_data(addr, 0x2D) & 0x08 == 0
    assert bus.read_i2c_block_data(addr, 0x1D, 2) != [0x80, 0x00]  # a temperature now


#: DS-000347 non-zero reset values of user banks 1, 2 and 4 (§15 user bank 1 register
#: descriptions, then banks 2 and 4), as transcribed per register by qunkejiang/alpakka_qk
#: main/src/bsp/ICM42688.h and Witty-Wizard/InertialIO src/ICM42688/Registers.h: (bank,
#: register, value). Bank 1: SENSOR_CONFIG0, GYRO_CONFIG_STATIC2..5, GYRO_CONFIG_STATIC10,
#: INTF_CONFIG4, INTF_CONFIG6; bank 2: ACCEL_CONFIG_STATIC2..4; bank 4: APEX_CONFIG1..8.
ICM42688P_BANK_1_2_4_RESET = (
    (1, 0x03, 0x80), (1, 0x0B, 0xA0), (1, 0x0C, 0x0D), (1, 0x0D, 0xAA), (1, 0x0E, 0x80),
    (1, 0x13, 0x11), (1, 0x7A, 0x83), (1, 0x7C, 0x5F),
    (2, 0x03, 0x30), (2, 0x04, 0x40), (2, 0x05, 0x62),
    (4, 0x40, 0xA2), (4, 0x41, 0x85), (4, 0x42, 0x51), (4, 0x43, 0xA4), (4, 0x44, 0x8C),
    (4, 0x45, 0x5C), (4, 0x46, 0x45), (4, 0x47, 0x5B),
)


#: One real ICM-42688-P's self-test run as kriswiner/ICM42688 issue #6 prints it (2022-08-18):
#: per axis the difference (mg, °/s) and the ratio (%) of the repository's ICM42688::selfTest
#: (ICM42688.cpp:195-200: ratio = difference in counts / (1310 or 2620 · 1.01^(code − 1) + 0.5)),
#: with the resolutions the report prints (ares 6.10352e-05 g, gres 0.00762939 °/s per count).
ISSUE6_ACCEL = ((95.1538, 92.7708), (106.567, 95.001), (724.304, 218.31))
ISSUE6_GYRO = ((13.5269, 12.4669), (13.7253, 12.4005), (13.7405, 12.4143))


def issue6_codes():
    """The part's codes, (bank, register, code): each difference / ratio solved for the code."""
    rows = []
    for bank, register, base, res, runs in ((2, 0x3B, 1310, 6.10352e-05 * 1000, ISSUE6_ACCEL),
                                            (1, 0x5F, 2620, 0.00762939, ISSUE6_GYRO)):
        for i, (diff, ratio) in enumerate(runs):
            otp = diff / res / (ratio / 100)
            code = 1 + math.log((otp - 0.5) / base) / math.log(1.01)
            assert abs(code - round(code)) < 1e-3  # the figures solve to whole codes
            rows.append((bank, register + i, round(code)))
    return rows


def test_icm42688p_self_test_codes_are_the_reported_parts():
    clock, bus, addr, _ = chip("icm42688p")
    for bank, register, code in issue6_codes():
        bus.write_byte_data(addr, 0x76, bank)
        assert bus.read_byte_data(addr, register) == code, (bank, hex(register))


def icm42688p_bank_registers(bus, addr):
    """Every register of banks 1, 2 and 4 but REG_BANK_SEL, as (bank, register) → value; then
    bank 0 again."""
    values = {}
    for bank in (1, 2, 4):
        bus.write_byte_data(addr, 0x76, bank)  # REG_BANK_SEL
        values.update({(bank, r): bus.read_byte_data(addr, r) for r in range(0x80) if r != 0x76})
    bus.write_byte_data(addr, 0x76, 0)
    return values


def test_icm42688p_banks_1_2_4_reset_values_after_power_on_and_soft_reset():
    clock, bus, addr, _ = chip("icm42688p")
    expected = {(bank, r): v for bank, r, v in (*ICM42688P_BANK_1_2_4_RESET, *issue6_codes())}
    got = icm42688p_bank_registers(bus, addr)
    assert {k: v for k, v in got.items() if v} == expected  # the listed ones, and 0 elsewhere
    for bank, register, _ in (*ICM42688P_BANK_1_2_4_RESET, *issue6_codes()):
        bus.write_byte_data(addr, 0x76, bank)
        bus.write_byte_data(addr, register, 0x00)
    bus.write_byte_data(addr, 0x76, 0)
    bus.write_byte_data(addr, 0x11, 0x01)  # DEVICE_CONFIG.SOFT_RESET restores them
    assert {k: v for k, v in icm42688p_bank_registers(bus, addr).items() if v} == expected


def test_lsm6dsox_status_reg_set_on_new_data_cleared_by_reading_each_output():
    clock, bus, addr, _ = chip("lsm6dsox")
    assert bus.read_byte_data(addr, 0x1E) == 0
    bus.write_byte_data(addr, 0x11, 0x40)  # CTRL2_G: 104 Hz
    clock.sleep(0.02)
    assert bus.read_byte_data(addr, 0x1E) == 0x06  # GDA, TDA; the accelerometer is off
    bus.write_byte_data(addr, 0x10, 0x40)  # CTRL1_XL: 104 Hz
    clock.sleep(0.02)
    assert bus.read_byte_data(addr, 0x1E) == 0x07
    bus.read_i2c_block_data(addr, 0x22, 6)  # OUTX_L_G..OUTZ_H_G
    assert bus.read_byte_data(addr, 0x1E) == 0x05
    bus.read_i2c_block_data(addr, 0x28, 6)  # OUTX_L_A..
    bus.read_i2c_block_data(addr, 0x20, 2)  # OUT_TEMP
    assert bus.read_byte_data(addr, 0x1E) == 0x00
    clock.sleep(0.02)
    assert bus.read_byte_data(addr, 0x1E) == 0x07
