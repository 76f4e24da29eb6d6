"""The LSM9DS1 gyro bandwidth is the one the driver reports: it routes the LPF2 output to the
data (CTRL_REG2_G.OUT_SEL = 10, datasheet Figure 28) and the emulated chip passes a sine at the
datasheet's cutoff (Tables 46–47) at −3 dB."""

import math

import numpy as np
import pytest

from gyrocal.drivers.clock import VirtualClock
from gyrocal.drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from gyrocal.drivers.emulated.motion import FunctionMotion
from gyrocal.drivers.imu import open_imu

DEG = math.pi / 180
QUIET = SensorTruth()  # the typical noise (a gyro with none looks stuck); seed fixed below


def gain_at(freq_hz, odr_hz, lowpass_hz=None, registers=None):
    """Amplitude gain of the gyro path for a 200 °/s sine at ``freq_hz`` (x axis), measured by a
    least-squares sine fit to 0.5 s of FIFO samples after 0.5 s of settling."""
    clock = VirtualClock()
    amp = 200 * DEG
    motion = FunctionMotion(lambda t: np.column_stack(
        [amp * np.sin(2 * np.pi * freq_hz * t), 0 * t, 0 * t]))
    bus, addr = make_emulated_imu("lsm9ds1", clock, motion, QUIET, subsamples=1, seed=5)
    reader = open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=500, odr_hz=odr_hz,
                      lowpass_hz=lowpass_hz)
    for reg, value in (registers or {}).items():
        bus.write_byte_data(addr, reg, value)
    reader.start()
    t, g = [], []
    while clock.monotonic() < 1.0:
        clock.sleep(0.01)
        b = reader.read()
        t.append(b.t)
        g.append(b.rate[:, 0])
    t, g = np.concatenate(t), np.concatenate(g)
    keep = t > t[0] + 0.5
    t, g = t[keep], g[keep]
    basis = np.column_stack([np.sin(2 * np.pi * freq_hz * t), np.cos(2 * np.pi * freq_hz * t)])
    coef, *_ = np.linalg.lstsq(basis, g, rcond=None)
    return float(np.hypot(*coef)) / amp, reader, bus.device(addr)


@pytest.mark.parametrize(("odr", "cutoff"), [(238.0, 29.0), (238.0, 78.0), (952.0, 58.0),
                                             (476.0, 21.0)])
def test_the_drivers_bandwidth_is_the_chips(odr, cutoff):
    # ST Table 47: 238 Hz: 14/29/63/78 Hz; 476 Hz: 21/28/57/100 Hz; 952 Hz: 33/40/58/100 Hz
    gain, reader, chip = gain_at(cutoff, odr, lowpass_hz=cutoff)
    assert chip.cutoff_hz() == cutoff
    assert gain == pytest.approx(1 / math.sqrt(2), abs=0.01)
    # a tenth of the cutoff passes (a first-order response: 1/sqrt(1 + 0.01) ≈ 0.995)
    low, *_ = gain_at(cutoff / 10, odr, lowpass_hz=cutoff)
    assert low == pytest.approx(1.0, abs=0.01)


def test_with_out_sel_00_the_output_is_lpf1_whatever_bw_g_says():
    # Figure 28: OUT_SEL = 00 takes the data after LPF1 (Table 46: 76 Hz at 238 Hz); BW_G only
    # acts on LPF2
    gain, _, chip = gain_at(76.0, 238.0, lowpass_hz=14.0, registers={0x11: 0x00})
    assert chip.cutoff_hz() == 76.0
    assert gain == pytest.approx(1 / math.sqrt(2), abs=0.01)


def test_the_driver_writes_out_sel_for_the_lpf2_path():
    clock = VirtualClock()
    bus, addr = make_emulated_imu("lsm9ds1", clock, subsamples=1)
    open_imu("lsm9ds1", bus, addr, clock=clock, range_dps=500, odr_hz=238.0, lowpass_hz=63.0)
    assert bus.read_byte_data(addr, 0x11) & 0x03 == 0b10  # CTRL_REG2_G.OUT_SEL
    assert bus.read_byte_data(addr, 0x10) & 0x03 == 0b10  # BW_G for 63 Hz
