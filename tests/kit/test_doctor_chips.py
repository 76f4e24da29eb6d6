"""`gyrocal doctor` names the chip on the bus when it is not the configured one (issue 15)."""

import pytest

from gyrocal.kit.cli import main


@pytest.mark.parametrize("model", ["icm42688p", "lsm9ds1", "icm20948", "lsm6dsox"])
def test_doctor_names_another_supported_chip_and_says_what_to_set(model, capsys):
    address = {"icm42688p": "0x68", "lsm9ds1": "0x6B", "icm20948": "0x68",
               "lsm6dsox": "0x6A"}[model]
    assert main(["doctor", "--sim", "--imu-model", "mpu9250",
                 "--sim-fault", f"imu-chip:{model}"]) == 4
    out = capsys.readouterr().out
    assert f"{address}: " in out and f"model '{model}'" in out
    assert f"--imu-model {model} --imu-address {address}" in out
    assert "IMU (mpu9250" not in out  # the configured check is not run against another chip


def test_doctor_on_an_emulated_icm42688p(capsys):
    assert main(["doctor", "--sim", "--imu-model", "icm42688p"]) == 0
    out = capsys.readouterr().out
    assert "0x68: ICM-42688-P (WHO_AM_I 0x47)" in out and "found icm42688p" in out


def test_an_unknown_chip_for_the_fault_is_bad_input(capsys):
    assert main(["doctor", "--sim", "--sim-fault", "imu-chip:bmi088"]) == 2
    assert "unknown IMU model 'bmi088'" in capsys.readouterr().err
