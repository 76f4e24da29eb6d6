"""A failed consistency verdict names the likely causes in order (issue 28): on the diagonal
model (protocols paper and auto) the model itself first, with `--protocol full`; then slip, then
saturation. The full model leaves no cross-axis term out, so it starts at the slip."""

from gyrocal.calib.model import Consistency, GyroCalibration
from gyrocal.kit.report import calibration_table

FAILED = Consistency(chi2=1879.0, dof=27, p_value=0.0, ok=False)
EYE = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def test_a_failed_diagonal_fit_names_the_model_first_then_slip_then_saturation():
    text = calibration_table(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                                             consistency=FAILED))
    model, slip, saturation = (text.index(w) for w in ("(1) the model is too simple",
                                                       "(2) the sensor slipped",
                                                       "(3) the gyro saturated"))
    assert model < slip < saturation and "--protocol full" in text
    assert "repeat the run" in text[slip:saturation]


def test_a_failed_full_fit_starts_at_the_slip():
    text = calibration_table(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                                             matrix=EYE, consistency=FAILED))
    assert "(1) the sensor slipped" in text and "(2) the gyro saturated" in text
    assert "too simple" not in text


def test_a_consistent_fit_names_no_cause():
    ok = Consistency(chi2=27.0, dof=27, p_value=0.46, ok=True)
    text = calibration_table(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0),
                                             consistency=ok))
    assert "likely causes" not in text
