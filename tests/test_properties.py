"""Property tests (hypothesis): invariants that must hold for every input, not just examples."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.drivers.emulated.dxl.protocol import crc16, remove_stuffing, stuff

# Within the domain a calibration document may hold (calib.model.LIMITS).
bias_values = st.floats(min_value=-100, max_value=100, allow_nan=False)  # rad/s
scales = st.floats(min_value=0.1, max_value=10, allow_nan=False)
positive = st.floats(min_value=1e-6, max_value=1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(scale=st.tuples(scales, scales, scales),
       bias=st.tuples(bias_values, bias_values, bias_values),
       std=st.tuples(positive, positive, positive), p=st.floats(0, 1))
def test_calibration_v1_round_trips_exactly(scale, bias, std, p):
    cal = GyroCalibration(scale=scale, bias=bias, scale_std=std, bias_std=std,
                          covariance=np.diag([*std, *std]) ** 2, method="paired-axis",
                          iterations=3, consistency=Consistency(1.0, 5, p, p >= 0.01))
    back = GyroCalibration.from_json(cal.to_json())
    assert back.to_dict() == cal.to_dict()
    m = np.array([0.5, -1.0, 2.0])
    np.testing.assert_array_equal(back.apply(m), cal.apply(m))


cross = st.floats(min_value=-0.05, max_value=0.05, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(diag=st.tuples(scales, scales, scales), off=st.lists(cross, min_size=6, max_size=6),
       bias=st.tuples(bias_values, bias_values, bias_values),
       m=st.lists(st.floats(-50, 50, allow_nan=False), min_size=3, max_size=3),
       var=st.floats(0, 1e-3))
def test_calibration_v2_round_trips_and_applies_the_matrix(diag, off, bias, m, var):
    a = np.diag(diag)
    a[~np.eye(3, dtype=bool)] = off
    cal = GyroCalibration(scale=diag, bias=bias, matrix=a, matrix_std=np.full((3, 3), var),
                          covariance=np.eye(12) * var, frame="f")
    back = GyroCalibration.from_json(cal.to_json())
    assert back.to_dict() == cal.to_dict()
    np.testing.assert_array_equal(back.full_matrix, a)
    # Eq. g = A (m + b) written out, row by row.
    g = [sum(a[i, j] * (m[j] + bias[j]) for j in range(3)) for i in range(3)]
    np.testing.assert_allclose(back.apply(m), g, rtol=1e-12, atol=1e-12)


def _bitwise_crc(data: bytes) -> int:
    """CRC-16 poly 0x8005, init 0, no reflection (hardware reference §4.2), bit by bit."""
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=64))
def test_byte_stuffing_round_trips_and_leaves_no_header_in_the_body(body):
    stuffed = stuff(body)
    assert remove_stuffing(stuffed) == body
    # After stuffing, FF FF FD only ever appears followed by FD (hardware reference §4.3).
    for i in range(len(stuffed) - 2):
        if stuffed[i : i + 3] == b"\xff\xff\xfd":
            assert i + 3 < len(stuffed) and stuffed[i + 3] == 0xFD


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=128))
def test_table_crc_equals_the_bitwise_definition(data):
    assert crc16(data) == _bitwise_crc(data)
