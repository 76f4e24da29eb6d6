"""Bad input ends in a message in the user's terms and exit 2, never a traceback (issue 11)."""

from pathlib import Path

import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main


def run(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


@pytest.fixture
def cal_file(tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(GyroCalibration(scale=(1.0, 1.0, 1.0), bias=(0.0, 0.0, 0.0)).to_json())
    return str(path)


@pytest.fixture
def a_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("existing.txt").write_text("keep me\n")
    return "existing.txt"


def _out_argv(command, flag, path, cal_file):
    return {
        "calibrate": ["calibrate", "--sim", "--quiet", "--out", path],
        "verify": ["verify", cal_file, "--sim", "--out", path],
        "study": ["study", "--preset", "normal", "--sensors", "1", "--reps", "1", "--plot", path],
    }[command]


@pytest.mark.parametrize("command", ["calibrate", "verify", "study"])
def test_an_output_directory_that_is_a_file_is_refused(command, a_file, cal_file, capsys):
    flag = "--plot" if command == "study" else "--out"
    code, err = run(_out_argv(command, flag, a_file, cal_file), capsys)
    assert code == 2
    assert f"{flag} existing.txt is a file; give a new or existing directory" in err
    assert Path(a_file).read_text() == "keep me\n"


@pytest.mark.parametrize("command", ["calibrate", "verify", "study"])
def test_an_output_directory_under_a_file_is_refused(command, a_file, cal_file, capsys):
    flag = "--plot" if command == "study" else "--out"
    code, err = run(_out_argv(command, flag, "existing.txt/sub", cal_file), capsys)
    assert code == 2
    assert f"{flag} existing.txt/sub is under existing.txt, which is a file" in err


def test_a_plot_file_under_a_file_names_the_file_in_the_way(a_file, capsys):
    pytest.importorskip("matplotlib")
    code, err = run(["noise", "--sim", "--duration", "60", "--plot", "existing.txt/x.png"], capsys)
    assert code == 2
    assert "existing.txt/x.png" in err and "existing.txt is a file" in err
    assert "does not exist" not in err


@pytest.mark.parametrize(
    "argv",
    [
        ["calibrate", "--sim", "--sim-seed", "-1"],
        ["calibrate", "--sim", "--sim-noise-seed", "-3"],
        ["doctor", "--sim", "--sim-seed", "-1"],
        ["verify", "CAL", "--sim", "--sim-seed", "-1"],
        ["track", "--live", "--sim", "--sim-seed", "-1"],
        ["track", "--sim", "--seed", "-1"],
        ["simulate-recording", "x", "--seed", "-1"],
        ["emulate", "--pty", "--seed", "-1"],
        ["noise", "--sim", "--seed", "-1"],
        ["study", "--seed", "-1"],
    ],
)
def test_a_negative_seed_is_a_usage_error(argv, cal_file, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = [cal_file if a == "CAL" else a for a in argv]
    code, err = run(argv, capsys)
    assert code == 2
    assert "seeds are whole numbers >= 0, got -" in err
    assert not Path("x").exists()


@pytest.mark.parametrize("command", ["calibrate", "doctor", "verify"])
def test_a_config_that_is_a_directory_is_refused(command, cal_file, tmp_path, capsys):
    argv = [command, *([cal_file] if command == "verify" else []), "--sim"]
    code, err = run([*argv, "--config", str(tmp_path)], capsys)
    assert code == 2
    assert f"--config {tmp_path} is a directory; give the config file itself" in err


@pytest.mark.parametrize(
    ("typed", "message"),
    [
        ("banana", "'banana' is not an I2C address; give it in hex like 0x68"),
        ("0x99", "0x99 is outside the 7-bit I2C addresses a device may use, 0x03..0x77"),
        ("2", "2 is outside the 7-bit I2C addresses"),
    ],
)
def test_an_imu_address_is_checked_and_echoed_as_typed(typed, message, capsys):
    code, err = run(["doctor", "--sim", "--imu-address", typed], capsys)
    assert code == 2
    assert message in err
    assert "<lambda>" not in err and "153" not in err


def test_an_imu_address_in_a_config_file_is_echoed_in_hex(tmp_path, capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text("[imu]\naddress = 0x99\n")
    code, err = run(["doctor", "--sim", "--config", str(cfg)], capsys)
    assert code == 2
    assert "(got 0x99)" in err


def test_a_file_output_that_is_a_directory_is_refused(tmp_path, capsys):
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.fileio import atomic_write_text

    with pytest.raises(InputError, match="is a directory; give a file name"):
        atomic_write_text(tmp_path, "x", force=True)


def test_doctor_sim_does_not_warn_about_its_own_emulator(capsys):
    assert main(["doctor", "--sim"]) == 0
    out = capsys.readouterr().out
    assert "Return Delay" not in out and "warn" not in out
    assert "`gyrocal calibrate --sim`" in out


def test_sim_notes_the_bus_settings_it_does_not_use(tmp_path, capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text("[gimbal]\nbaud = 115200\n")
    assert main(["doctor", "--sim", "--config", str(cfg)]) == 0
    err = capsys.readouterr().err
    assert "note: --sim runs the emulated servos" in err and "gimbal.baud (115200)" in err
    assert main(["doctor", "--sim"]) == 0  # nothing set by the user: nothing to note
    assert "note" not in capsys.readouterr().err


def test_a_silent_servo_leads_with_the_cause_in_words(tmp_path, capsys):
    code, err = run(["calibrate", "--sim", "--quiet", "--out", str(tmp_path / "o"),
                     "--sim-fault", "silent:2:5"], capsys)
    assert code == 4
    message = err.split("gyrocal: error: ", 1)[1]
    assert message.startswith("SYNC_READ") and "no status packet" in message
    assert "The safe stop then could not confirm torque off on servo(s) 2" in message
    assert "Error(" not in message  # no Python repr of the cause


@pytest.mark.parametrize("preset", ["demo", "convergence"])
def test_study_plot_on_a_preset_without_plots_says_so(preset, tmp_path, capsys):
    code, err = run(["study", "--preset", preset, "--plot", str(tmp_path / "p")], capsys)
    assert code == 2
    assert f"the {preset} preset draws no plots (only normal, extreme, speed-sweep do)" in err
    assert not (tmp_path / "p").exists()


def test_an_odr_the_chip_cannot_do_exactly_is_rounded_with_a_note(capsys):
    # MPU-9250: 1 kHz/(1 + SMPLRT_DIV); 201 Hz runs at 200 Hz and the user is told.
    assert main(["doctor", "--sim", "--odr", "201"]) == 0
    out, err = capsys.readouterr()
    assert "imu.odr_hz 201 is not a rate the mpu9250 can do; it runs at the nearest, 200 Hz" in err
    assert "200 Hz" in out
    assert main(["doctor", "--sim", "--odr", "200"]) == 0
    assert "imu.odr_hz" not in capsys.readouterr().err
