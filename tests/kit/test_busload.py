"""The planned I²C bus load (kit.busload): the formula against figures worked out by hand, and
``gyrocal calibrate`` refusing a plate one bus cannot carry before anything moves, with what to
do; the same sensors on two buses pass."""

import pytest

from gyrocal.kit.busload import bus_loads, check_bus_loads, sample_bytes
from gyrocal.kit.cli import main
from gyrocal.kit.errors import InputError

FOUR_1K = [{"name": n, "model": m, "bus": 1, "odr_hz": r}
           for n, m, r in (("mpu", "mpu9250", 1000.0), ("icm", "icm42688p", 1000.0),
                           ("st1", "lsm6dsox", 833.0), ("st2", "lsm6dsox", 833.0))]


def test_load_worked_out_by_hand():
    # one MPU-9250 at 1 kHz on 400 kHz: 14-byte frames, 3 bytes of addressing per 32-byte block,
    # a 5-byte FIFO count read per 200 Hz loop, 9 bits a byte
    (b,) = bus_loads([{"name": "x", "model": "mpu9250", "bus": 1, "odr_hz": 1000.0}], 200.0)
    assert b.bus == 1 and b.load == pytest.approx(9 * (14 * 1000 * 35 / 32 + 5 * 200) / 400e3)
    # an LSM6DSOX sample is three 7-byte words (timestamp, gyro, accelerometer)
    (b,) = bus_loads([{"model": "lsm6dsox", "bus": 2, "odr_hz": 416.0}], 100.0)
    assert b.load == pytest.approx(9 * (21 * 416 * 35 / 32 + 5 * 100) / 400e3)


@pytest.mark.parametrize("model,frame", [
    ("mpu9250", 14), ("mpu6500", 14),  # FIFO frame: accel 6, temperature 2, gyro 6
    ("icm20948", 14),  # FIFO_EN_2 frame ACCEL_XOUT_H..TEMP_OUT_L (DS-000189)
    ("icm42688p", 16),  # FIFO packet 3: header, accel 6, gyro 6, temperature 1, timestamp 2
    ("lsm9ds1", 12),  # FIFO slot: gyro 6 + accel 6
    ("lsm6dsox", 21),  # three FIFO words of tag + 6 bytes: timestamp, gyro, accel
])
def test_bytes_per_sample_are_the_chips_fifo_frames(model, frame):
    assert sample_bytes(model) == frame


def test_four_sensors_at_1khz_are_refused_on_one_bus_and_on_two():
    """One bus: 169 % of its bits. Two buses (82 % and 87 % each): the loop reads them in turn,
    so together they still need 169 % of its time (bench multi, Table 1b: samples lost)."""
    with pytest.raises(InputError, match=r"I2C bus 1 .* would carry 169 % .*lower odr_hz"):
        check_bus_loads(FOUR_1K, 200.0)
    two = [{**s, "bus": 1 + k % 2} for k, s in enumerate(FOUR_1K)]  # one InvenSense, one ST each
    loads = {b.bus: round(100 * b.load) for b in bus_loads(two, 200.0)}
    assert loads == {1: 82, 2: 87}
    with pytest.raises(InputError, match=r"the 2 I2C buses together would need 169 % .*adds "
                                         r"wires, not time"):
        check_bus_loads(two, 200.0)
    # at about 500 Hz (the bench's loss-free level): 89 %, neither refused nor warned
    half = [{**s, "odr_hz": {1000.0: 500.0, 833.0: 416.0}[s["odr_hz"]]} for s in two]
    assert check_bus_loads(half, 200.0) == []
    # a bus near its limit (45 + 42 + 9 = 96 %) is warned about, with what to do
    near = [{"model": "lsm6dsox", "bus": 3, "odr_hz": 833.0},
            {"model": "icm42688p", "bus": 3, "odr_hz": 1000.0},
            {"model": "mpu9250", "bus": 3, "odr_hz": 200.0}]
    (w,) = check_bus_loads(near, 200.0)
    assert "I2C bus 3 at 400 kHz would carry 96 %" in w and "may be lost" in w
    assert "lower odr_hz" in w


def test_calibrate_refuses_an_overloaded_bus_before_the_jig_moves(tmp_path, capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text("".join(
        f'[[imu]]\nname = "{s["name"]}"\nmodel = "{s["model"]}"\naddress = {a}\n'
        f'odr_hz = {s["odr_hz"]}\n' for s, a in zip(FOUR_1K, (0x68, 0x69, 0x6A, 0x6B),
                                                    strict=True)))
    out = tmp_path / "run"
    code = main(["calibrate", "--sim", "--config", str(cfg), "--out", str(out), "--quiet",
                 "--no-report"])
    err = capsys.readouterr().err
    assert code == 2
    assert "would carry 169 %" in err and "FIFOs would overflow" in err and "odr_hz" in err
    assert not any(out.rglob("manifest.json"))  # nothing recorded
