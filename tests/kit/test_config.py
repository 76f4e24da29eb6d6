import tomllib

import pytest

from gyrocal.kit.cli import main
from gyrocal.kit.config import SCHEMA, apply_overrides, default_config, load_config, template
from gyrocal.kit.errors import InputError


def test_template_parses_back_to_the_defaults(tmp_path):
    assert tomllib.loads(template()) == default_config().sections
    p = tmp_path / "g.toml"
    p.write_text(template())
    assert load_config(p).sections == default_config().sections
    assert all(f"[{s}]" in template() for s in SCHEMA)


def test_values_override_defaults(tmp_path):
    p = tmp_path / "g.toml"
    p.write_text('[imu]\nmodel = "lsm9ds1"\naddress = 0x6B\n[gimbal]\nids = [4, 5, 6]\n'
                 'axes = ["z", "-x", "y"]\n')
    cfg = load_config(p)
    assert cfg["imu"]["model"] == "lsm9ds1" and cfg["imu"]["address"] == 0x6B
    assert cfg.axis_of() == {4: "z", 5: "-x", 6: "y"}
    assert cfg["imu"]["odr_hz"] == 200.0  # untouched default


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[imu]\nmodle = 'x'\n", r"unknown key imu.modle; allowed in \[imu\]: model, bus"),
        ("[servo]\nport = 'x'\n", r"unknown section \[servo\]; allowed: gimbal, imu, protocol"),
        ("[imu]\nmodel = 'bmi160'\n", "imu.model is 'bmi160'; allowed: 'mpu9250'"),
        ("[imu]\nodr_hz = -5\n", "imu.odr_hz must be in 1..8000"),
        ("[imu]\nbus = 'one'\n", "imu.bus must be int"),
        ("[gimbal]\naxes = ['x', 'y', 'w']\n", "gimbal.axes has unknown axes"),
        ("[gimbal]\naxes = ['x', 'x', 'z']\n", "must name each of x, y and z once"),
        ("[gimbal]\nids = [1, 1, 2]\n", "gimbal.ids must be distinct"),
        ("[gimbal]\nids = [1, 2]\n", "gimbal.ids has 2 servos but gimbal.axes names 3"),
        ("[imu]\naddress = 0x90\n", "7-bit I2C address"),
        ("[protocol]\nname = 'fast'\n", "allowed: 'full', 'auto', 'paper'"),
        ("[imu\n", "not valid TOML"),
    ],
)
def test_bad_config_names_the_key_and_the_allowed_values(tmp_path, text, message):
    p = tmp_path / "g.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=message):
        load_config(p)


def test_missing_file_says_how_to_make_one(tmp_path):
    with pytest.raises(InputError, match="gyrocal init"):
        load_config(tmp_path / "none.toml")


def test_overrides_are_validated_too():
    cfg = apply_overrides(default_config(), {"imu.range_dps": 1000, "gimbal.port": None})
    assert cfg["imu"]["range_dps"] == 1000 and cfg["gimbal"]["port"] == "/dev/ttyUSB0"
    with pytest.raises(InputError, match="imu.range_dps is 300"):
        apply_overrides(default_config(), {"imu.range_dps": 300})


def test_init_writes_once(tmp_path, capsys):
    p = tmp_path / "gyrocal.toml"
    assert main(["init", str(p)]) == 0
    assert load_config(p).sections == default_config().sections
    assert main(["init", str(p)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["init", str(p), "--force"]) == 0


def test_the_method_choices_are_the_estimators():
    from gyrocal.calib.estimators import METHODS as ESTIMATORS
    from gyrocal.kit.config import METHODS

    assert METHODS[0] == "auto"  # kit.pipeline's choice between the full and diagonal models
    assert set(METHODS[1:]) == set(ESTIMATORS)
