"""The factory self-test of the emulated InvenSense chips that share the MPU-9250's design
(MPU-9250 and ICM-20948): codes in read-back registers, and the actuation their enable bits
turn on.

Both chips keep one factory self-test code per axis and sensor (MPU-9250: SELF_TEST_X/Y/Z_GYRO
0x00-0x02 and _ACCEL 0x0D-0x0F, RM-MPU-9250A-00; ICM-20948: the same six in user bank 1 at
0x02-0x04 and 0x0E-0x10, DS-000189) and an enable bit per axis that moves that axis's output by
the response the code stands for, ``2620 / 2^FS · 1.01^(code − 1)`` counts at the range FS
(AN-MPU-9250A-03; :func:`~gyrocal.drivers.imu.chips.mpu9250_self_test_otp`, whose comment
cites TDK's own ICM-20948 code for the same formula). Only where the registers sit differs:
:class:`SelfTestLayout` says where, :func:`self_test_counts` computes the actuation, and
:data:`FACTORY_SELF_TEST_CODES` holds the codes an emulated part carries.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gyrocal.drivers.imu.chips import mpu9250_self_test_otp

__all__ = ["FACTORY_SELF_TEST_CODES", "SelfTestLayout", "self_test_counts"]

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
        The shift of the 3-bit enable field: X in its top bit, then Y, then Z.
    fs : int
        The register holding the sensor's 2-bit full-scale field.
    fs_shift : int
        That field's shift.
    """

    code_x: int
    enable: int
    enable_shift: int
    fs: int
    fs_shift: int

    def codes_reset(self, codes: Sequence[int]) -> dict[int, int]:
        """The code registers' reset values: ``codes`` (X, Y, Z) at ``code_x`` onwards."""
        return {self.code_x + i: int(c) for i, c in enumerate(codes)}


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
    enabled = (config[layout.enable] >> layout.enable_shift) & 0b111
    on = [bool(enabled & (0b100 >> i)) for i in range(3)]
    if not any(on):
        return 0.0
    fs = (config[layout.fs] >> layout.fs_shift) & 0x03
    return np.array([mpu9250_self_test_otp(codes[layout.code_x + i], fs) if on[i] else 0.0
                     for i in range(3)])
