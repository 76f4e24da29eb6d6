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
        (lambda d: d.update(version=3), "version 3 is not supported"),
        (lambda d: d.update(version=2), "version 2 calibration lacks the field 'matrix'"),
        (lambda d: d.pop("scale"), "lacks the field 'scale'"),
        (lambda d: d.update(scale=[1.0, 1.0]), "'scale' must be a list of 3"),
        (lambda d: d.update(bias=[0.0, "x", 0.0]), r"'bias\[1\]' must be a number"),
        (lambda d: d.update(scale=[1.0, -1.0, 1.0]), r"'scale\[1\]' is -1, outside "
                                                     r"its domain \[0.1, 10\]"),
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


# ---------------------------------------------------------------- Calibration v2 (issue 10)
A = ((1.01, 0.012, -0.004), (-0.008, 0.99, 0.019), (0.003, -0.015, 1.002))
KIN = {"chain": [1, 2, 3], "axes": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
       "reference_angles_rad": [0.0, 0.1, -0.2]}


def make_full(**kw):
    base = dict(
        scale=(1.01, 0.99, 1.002),
        bias=(0.01, -0.02, 0.003),
        bias_std=(1e-3, 2e-3, 3e-3),
        covariance=np.diag(np.arange(1, 13) * 1e-8),
        matrix=A,
        matrix_std=np.full((3, 3), 1e-4) + np.diag([1e-4, 2e-4, 3e-4]),
        frame="x-gyro-xy-plane",
        kinematics=KIN,
        method="full-model",
        sensor={"model": "mpu9250"},
    )
    base.update(kw)
    return GyroCalibration(**base)


def test_full_model_apply_is_the_matrix_product_written_out():
    cal = make_full()
    m = [0.5, -1.0, 2.0]
    b = cal.bias
    expected = [sum(A[i][j] * (m[j] + b[j]) for j in range(3)) for i in range(3)]
    np.testing.assert_allclose(cal.apply(m), expected, rtol=0, atol=1e-15)
    many = cal.apply([m, [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(many[0], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(many[1], [sum(A[i][j] * b[j] for j in range(3)) for i in range(3)])
    np.testing.assert_array_equal(cal.full_matrix, np.array(A))
    np.testing.assert_array_equal(make_cal().full_matrix, np.diag([1.01, 0.99, 1.002]))


def test_v2_document_carries_matrix_diagonals_and_twelve_by_twelve_covariance():
    cal = make_full()
    doc = json.loads(cal.to_json())
    assert doc["version"] == 2 and doc["model"] == "g = matrix @ (m + bias)"
    assert doc["matrix"] == [list(r) for r in A]
    assert doc["scale"] == [1.01, 0.99, 1.002]  # a v1 reader still sees the diagonal
    assert doc["scale_std"] == pytest.approx([2e-4, 3e-4, 4e-4], rel=1e-12)
    assert len(doc["covariance"]) == 12 and all(len(r) == 12 for r in doc["covariance"])
    assert doc["frame"] == "x-gyro-xy-plane" and doc["kinematics"] == KIN
    back = GyroCalibration.from_json(cal.to_json())
    assert back == cal and back.to_dict() == cal.to_dict() and back.kinematics == KIN
    assert back.is_full and not make_cal().is_full


def test_v1_document_is_unchanged_by_v2():
    doc = make_cal().to_dict()
    assert doc["version"] == 1 and not {"matrix", "matrix_std", "frame", "kinematics"} & set(doc)
    assert len(doc["covariance"]) == 6


def test_constructor_keeps_the_full_model_coherent():
    with pytest.raises(CalibInputError, match="diagonal of matrix"):
        make_full(scale=(1.0, 1.0, 1.0))
    with pytest.raises(CalibInputError, match="covariance must be 12x12"):
        make_full(covariance=np.eye(6))
    with pytest.raises(CalibInputError, match="need a matrix"):
        make_cal(kinematics=KIN)


def test_unknown_field_is_refused_with_did_you_mean():
    doc = make_cal().to_dict()
    doc["bias_sdt"] = doc.pop("bias_std")
    with pytest.raises(CalibrationFormatError,
                       match="unknown field 'bias_sdt'.*did you mean 'bias_std'"):
        GyroCalibration.from_dict(doc)
    doc = make_cal().to_dict()
    doc["matrix"] = [list(r) for r in A]  # a v2 field in a v1 document
    with pytest.raises(CalibrationFormatError, match="unknown field 'matrix' in a version 1"):
        GyroCalibration.from_dict(doc)
    doc = make_full().to_dict()
    doc["kinematics"]["axis"] = doc["kinematics"].pop("axes")
    with pytest.raises(CalibrationFormatError, match="did you mean 'axes'"):
        GyroCalibration.from_dict(doc)
    doc = make_cal().to_dict()
    doc["consistency"]["pvalue"] = 0.5
    with pytest.raises(CalibrationFormatError, match="did you mean 'p_value'"):
        GyroCalibration.from_dict(doc)


def _set(path, value):
    def mutate(d):
        *head, last = path
        for k in head:
            d = d[k]
        d[last] = value
    return mutate


@pytest.mark.parametrize(
    ("full", "mutate", "message"),
    [
        (False, _set(["consistency", "p_value"], 2.0), r"p_value' is 2, outside its domain \[0, 1"),
        (False, _set(["consistency", "p_value"], -0.1), r"p_value' is -0.1, outside"),
        (False, _set(["consistency", "chi2"], -3.0), r"chi2' is -3, outside"),
        (False, _set(["bias_std", 0], -1e-3), r"'bias_std\[0\]' is -0.001, outside"),
        (False, _set(["scale_std", 2], -1.0), r"'scale_std\[2\]' is -1, outside"),
        (False, _set(["covariance", 0, 3], math.nan), r"'covariance\[0\]\[3\]' must be a finite"),
        (False, _set(["covariance", 1, 1], -1e-8), "negative variance"),
        (False, _set(["temperature_c"], math.inf), "'temperature_c' must be a finite"),
        (False, _set(["temperature_c"], 1e6), r"'temperature_c' is 1e\+06, outside"),
        (False, _set(["scale", 0], 1e308), r"'scale\[0\]' is 1e\+308, outside its domain"),
        (False, _set(["scale", 0], 0.0146), r"'scale\[0\]' is 0.0146, outside"),
        (False, _set(["bias", 1], 1e5), r"'bias\[1\]' is 100000, outside"),
        (False, _set(["bias", 1], 10**401), "'bias\\[1\\]' is an integer of 402 digits"),
        (False, _set(["iterations"], 10**401), "'iterations' is an integer of 402 digits, outside"),
        (True, _set(["matrix", 0, 1], 0.0 + math.inf), r"'matrix\[0\]\[1\]' must be a finite"),
        (True, _set(["matrix", 0, 1], 1.5), "cross-axis term beyond"),
        (True, _set(["matrix", 1, 1], 0.5), "'scale' must be the diagonal of 'matrix'"),
        (True, _set(["matrix_std", 1, 0], -1e-4), r"'matrix_std\[1\]\[0\]' is -0.0001, outside"),
        (True, _set(["covariance"], [[0.0] * 6] * 6), "'covariance' must be a 12×12"),
        (True, _set(["kinematics", "axes", 1], [0.0, 2.0, 0.0]), "unit vectors"),
        (True, _set(["kinematics", "chain"], [1, 1, 3]), "distinct servo IDs"),
        (True, _set(["kinematics", "reference_angles_rad"], [0.0]), "list of 3 numbers"),
        (True, _set(["frame"], 3), "'frame' must be a string"),
    ],
)
def test_out_of_domain_documents_are_refused_naming_the_field(full, mutate, message):
    doc = (make_full() if full else make_cal()).to_dict()
    mutate(doc)
    with pytest.raises(CalibrationFormatError, match=message):
        GyroCalibration.from_dict(doc)


@pytest.mark.parametrize(
    "text",
    ['{"format": "gyrocal-calibration", "version": ' + "9" * 5000 + "}",
     "[" * 100000 + "]" * 100000],
)
def test_hostile_json_text_is_a_format_error(text):
    with pytest.raises(CalibrationFormatError, match="JSON"):
        GyroCalibration.from_json(text)


def test_the_home_pose_of_gravity_round_trips_and_older_documents_mean_unknown():
    kin = {**KIN, "home_angles_rad": [0.0, 0.5, -1.0], "up_servo": [3, -1]}
    cal = make_full(kinematics=kin)
    back = GyroCalibration.from_json(cal.to_json())
    assert back.kinematics == kin and back == cal
    home, up = back.gravity_reference
    np.testing.assert_array_equal(home, [0.0, 0.5, -1.0])
    assert up == (3, -1)
    assert make_full().gravity_reference is None  # a document without it: unknown
    assert make_cal().gravity_reference is None
    for bad, match in (
        ({**KIN, "home_angles_rad": [0.0, 0.0, 0.0]}, "go together"),
        ({**KIN, "up_servo": [3, 1]}, "go together"),
        ({**kin, "up_servo": [4, 1]}, r"servo ID of the chain \[1, 2, 3\], 1 or -1"),
        ({**kin, "up_servo": [3, 0]}, "1 or -1"),
        ({**kin, "home_angles_rad": [0.0, 0.0]}, "home_angles_rad"),
    ):
        doc = cal.to_dict()
        doc["kinematics"] = bad
        with pytest.raises(CalibrationFormatError, match=match):
            GyroCalibration.from_dict(doc)
