import json
import math

import numpy as np
import pytest

from gyrocal.calib.errors import CalibInputError, CalibrationFormatError
from gyrocal.calib.model import Consistency, GyroCalibration


def make_cal(**kw):
    base = dict(
        scale=(1.01, 0.99, 1.002),
        bias=(0.01, -0.02, 0.003),
        scale_std=(1e-4, 2e-4, 3e-4),
        bias_std=(1e-3, 2e-3, 3e-3),
        covariance=np.diag([1e-8, 4e-8, 9e-8, 1e-6, 4e-6, 9e-6]),
        method="paired-axis",
        iterations=4,
        consistency=Consistency(chi2=40.1, dof=45, p_value=0.68, ok=True),
        sensor={"model": "mpu9250", "odr_hz": 200.0},
        temperature_c=24.5,
        created="2026-11-21T10:00:00+00:00",
        source="simulation",
    )
    base.update(kw)
    return GyroCalibration(**base)


def test_apply_follows_paper_eq1_for_one_and_many_readings():
    cal = make_cal()
    m = np.array([0.5, -1.0, 2.0])
    expected = np.array([1.01 * (0.5 + 0.01), 0.99 * (-1.0 - 0.02), 1.002 * (2.0 + 0.003)])
    np.testing.assert_allclose(cal.apply(m), expected, rtol=0, atol=1e-15)
    many = np.vstack([m, 2 * m, -m])
    out = cal.apply(many)
    assert out.shape == (3, 3)
    np.testing.assert_allclose(out[1], np.array([1.01, 0.99, 1.002]) * (2 * m + cal.bias))


@pytest.mark.parametrize("bad", [np.zeros(2), np.zeros((4, 2)), np.zeros((2, 2, 3))])
def test_apply_refuses_wrong_shapes(bad):
    with pytest.raises(CalibInputError, match="shape"):
        make_cal().apply(bad)


def test_apply_refuses_nan():
    with pytest.raises(CalibInputError, match="NaN"):
        make_cal().apply([0.0, np.nan, 0.0])


def test_json_round_trip_is_exact():
    cal = make_cal(axes={"1": {"axis": [1.0, 0.0, 0.0], "misalignment_deg": 0.0}})
    text = cal.to_json()
    doc = json.loads(text)
    assert doc["format"] == "gyrocal-calibration" and doc["version"] == 1
    assert doc["model"] == "g = scale * (m + bias)"
    back = GyroCalibration.from_json(text)
    assert back.scale == cal.scale and back.bias == cal.bias
    assert back.covariance == cal.covariance
    assert back.consistency == cal.consistency
    assert back.sensor == cal.sensor and back.axes == cal.axes
    assert back.to_dict() == cal.to_dict()


def test_nan_uncertainties_become_null_and_back():
    cal = GyroCalibration(scale=(1, 1, 1), bias=(0, 0, 0))
    doc = cal.to_dict()
    assert doc["scale_std"] == [None, None, None]
    back = GyroCalibration.from_dict(doc)
    assert all(math.isnan(x) for x in back.scale_std)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.update(format="something-else"), "format"),
        (lambda d: d.update(version=2), "version 2 is not supported"),
        (lambda d: d.pop("scale"), "lacks the field 'scale'"),
        (lambda d: d.update(scale=[1.0, 1.0]), "'scale' must be a list of 3"),
        (lambda d: d.update(bias=[0.0, "x", 0.0]), "'bias' must be a list of 3 finite"),
        (lambda d: d.update(scale=[1.0, -1.0, 1.0]), "'scale' must be positive"),
        (lambda d: d.update(covariance=[[0.0] * 6] * 5), "covariance"),
        (lambda d: d.update(iterations=-1), "iterations"),
        (lambda d: d.update(consistency={"chi2": 1.0}), "consistency"),
        (lambda d: d.update(model="g = m"), "model"),
    ],
)
def test_malformed_documents_are_refused_with_the_field_named(mutate, message):
    doc = make_cal().to_dict()
    mutate(doc)
    with pytest.raises(CalibrationFormatError, match=message):
        GyroCalibration.from_dict(doc)


def test_invalid_json_text_is_a_format_error():
    with pytest.raises(CalibrationFormatError, match="not valid JSON"):
        GyroCalibration.from_json("{not json")


def test_constructor_validates():
    with pytest.raises(CalibInputError, match="scale must be positive"):
        GyroCalibration(scale=(1, 0, 1), bias=(0, 0, 0))
    with pytest.raises(CalibInputError, match="covariance must be 6x6"):
        GyroCalibration(scale=(1, 1, 1), bias=(0, 0, 0), covariance=np.eye(5))


def test_is_frozen():
    cal = make_cal()
    with pytest.raises(AttributeError):
        cal.scale = (2, 2, 2)  # type: ignore[misc]
