"""The factory self-test of the emulated InvenSense chips: codes in read-back registers, and
the actuation their enable bits turn on (MPU-9250, ICM-20948 and ICM-42688-P).

Each chip keeps one factory self-test code per axis and sensor (MPU-9250: SELF_TEST_X/Y/Z_GYRO
0x00-0x02 and _ACCEL 0x0D-0x0F, RM-MPU-9250A-00; ICM-20948: the same six in user bank 1 at
0x02-0x04 and 0x0E-0x10, DS-000189; ICM-42688-P: XG/YG/ZG_ST_DATA in user bank 1 at 0x5F-0x61
and XA/YA/ZA_ST_DATA in bank 2 at 0x3B-0x3D, DS-000347) and an enable bit per axis that moves
that axis's output by the response the code stands for, ``2620 / 2^FS · 1.01^(code − 1)``
counts, FS being the range's doublings above ±250 °/s or ±2 g (AN-MPU-9250A-03;
:func:`~gyrocal.drivers.imu.chips.mpu9250_self_test_otp`, whose comment cites TDK's own
ICM-20948 code for the same formula). The ICM-42688-P's FS_SEL codes count the other way (011 is
±250 °/s and ±2 g, lower codes wider ranges), and TDK writes its formula as
``2620 / 2^(3 − FS_SEL) · 1.01^(ST_code − 1)`` (eMD Icm426xxSelfTest.c line 62,
INV_ST_OTP_EQUATION; the same macro in TDK's icm4x6xx.c, and kriswiner/ICM42688 ICM42688.cpp:
195-200 at FS_SEL 2 and 3): the same response at the same range. Only where the registers sit
and how the range is coded differs: :class:`SelfTestLayout` says that, :func:`self_test_counts`
computes the actuation, and :data:`FACTORY_SELF_TEST_CODES` and
:data:`ICM42688P_FACTORY_SELF_TEST_CODES` hold the codes an emulated part carries.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gyrocal.drivers.imu.chips import mpu9250_self_test_otp

__all__ = ["FACTORY_SELF_TEST_CODES", "ICM42688P_FACTORY_SELF_TEST_CODES", "SelfTestLayout",
           "self_test_counts"]

#: Factory self-test codes (gyro X, Y, Z, then accelerometer X, Y, Z) an emulated MPU-9250 or
#: ICM-20948 holds: a stated stand-in ⚠ (no public register dump of a part's codes was found:
#: the self-test reports in kriswiner/MPU9250's issues give percentages, not codes), chosen so
#: that the responses they stand for (:func:`~gyrocal.drivers.imu.chips.mpu9250_self_test_otp`)
#: are about 94 °/s and 0.45 g: above the 60 °/s absolute gyro limit and inside the 225–675 mg
#: accelerometer range that TDK's MPU-6500-family self-test code applies when a part has no
#: codes (DEF_GYRO_ST_AL, DEF_ACCEL_ST_AL_MIN/MAX). The ICM-20948's own self-test (TDK eMD
#: Icm20948SelfTest.c, inv_check_accelgyro_self_test) has no absolute limits, only the ratio to
#: these codes, so the same codes serve it.
FACTORY_SELF_TEST_CODES = (0x9C, 0xA0, 0xA3, 0x68, 0x6B, 0x70)

#: Factory self-test codes (XG, YG, ZG_ST_DATA, then XA, YA, ZA_ST_DATA) an emulated
#: ICM-42688-P holds: one real part's, ⚠ one part in one report. kriswiner/ICM42688 issue #6
#: (2022-08-18) prints that part's self-test differences and ratios from the repository's
#: ``ICM42688::selfTest`` (ICM42688.cpp:195-200, ratio = difference / (1310 or 2620 ·
#: 1.01^(code − 1) + 0.5)), with the resolutions it scaled the differences by (ares 6.10352e-05,
#: gres 0.00762939); difference in counts / ratio gives each code back to within 5e-4 of an
#: integer: gyro 171, 173, 173 (responses 108.5, 110.7, 110.7 °/s at ±250 °/s, above TDK's
#: 60 °/s MIN_ST_GYRO_DPS) and accelerometer 26, 35, 144 (0.205, 0.224, 0.664 g, inside TDK's
#: 50-1200 mg MIN/MAX_ST_ACCEL_MG; Icm426xxSelfTest.c lines 67, 72-73). That run measured a
#: gyro response of 12 % of these (the report is of a failing gyro test); the codes are the
#: factory's whatever a run measures.
ICM42688P_FACTORY_SELF_TEST_CODES = (171, 173, 173, 26, 35, 144)


@dataclass(frozen=True)
class SelfTestLayout:
    """Where a chip keeps one sensor's (gyro's or accelerometer's) self-test.

    Parameters
    ----------
    code_x : int
        The X axis's factory code register; Y and Z follow it.
    enable : int
        The register holding the three enable bits.
    enable_shift : int
        The shift of the 3-bit enable field: X in its top bit, then Y, then Z (MPU-9250,
        ICM-20948), or X in its low bit with ``x_in_low_bit`` (ICM-42688-P SELF_TEST_CONFIG).
    fs : int
        The register holding the sensor's full-scale field.
    fs_shift : int
        That field's shift.
    x_in_low_bit : bool
        The enable field's X bit is its lowest (EN_GX_ST bit 0, EN_GY_ST bit 1, ...).
    fs_mask : int
        The full-scale field's mask after the shift (2 bits: 0x03; the ICM-42688-P's 3: 0x07).
    fs_of_base_range : int
        The full-scale code of ±250 °/s or ±2 g, where the response is 2620 counts times the
        code's factor (0 on the MPU-9250 and ICM-20948, 3 on the ICM-42688-P).
    fs_code_narrows : bool
        A higher full-scale code is a narrower range (ICM-42688-P: 000 is ±2000 °/s), so the
        formula's FS is ``fs_of_base_range − code`` (TDK's ``3 − FS``) rather than
        ``code − fs_of_base_range``.
    """

    code_x: int
    enable: int
    enable_shift: int
    fs: int
    fs_shift: int
    x_in_low_bit: bool = False
    fs_mask: int = 0x03
    fs_of_base_range: int = 0
    fs_code_narrows: bool = False

    def codes_reset(self, codes: Sequence[int]) -> dict[int, int]:
        """The code registers' reset values: ``codes`` (X, Y, Z) at ``code_x`` onwards."""
        return {self.code_x + i: int(c) for i, c in enumerate(codes)}

    def enabled_axes(self, config: Sequence[int] | bytearray) -> list[bool]:
        """Which of X, Y, Z have their self-test enable bit set in ``config``."""
        field = (config[self.enable] >> self.enable_shift) & 0b111
        bits = (0b001, 0b010, 0b100) if self.x_in_low_bit else (0b100, 0b010, 0b001)
        return [bool(field & b) for b in bits]

    def range_doublings(self, config: Sequence[int] | bytearray) -> int:
        """The configured range's doublings above ±250 °/s or ±2 g: the formula's FS."""
        code = (config[self.fs] >> self.fs_shift) & self.fs_mask
        step = code - self.fs_of_base_range
        return -step if self.fs_code_narrows else step


def self_test_counts(layout: SelfTestLayout, codes: Sequence[int] | bytearray,
                     config: Sequence[int] | bytearray) -> np.ndarray | float:
    """The counts the self-test adds to each axis's output at the configured range: the
    factory response its code stands for (AN-MPU-9250A-03) on each axis whose enable bit is
    set, 0 on the others.

    Parameters
    ----------
    layout : SelfTestLayout
        Where the sensor's self-test registers are.
    codes : sequence of int
        The register file (or user bank) holding the code registers.
    config : sequence of int
        The register file (or user bank) holding the enable and full-scale registers.

    Returns
    -------
    numpy.ndarray or float
        Three counts, or 0.0 when no axis is enabled.
    """
    on = layout.enabled_axes(config)
    if not any(on):
        return 0.0
    fs = layout.range_doublings(config)
    return np.array([mpu9250_self_test_otp(codes[layout.code_x + i], fs) if on[i] else 0.0
                     for i in range(3)])
