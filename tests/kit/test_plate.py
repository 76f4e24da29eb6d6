"""Several sensors on one plate: config, the emulated plate, one run calibrating each sensor.

Truth is each sensor's own (the emulator's truth in its recording's manifest, and the sensor's
truth rebuilt from the config by ``build_sim_plate``); the frame conversion is the test's own
(tests/calib/fullmodel_truth.truth_in_frame).
"""

import json

import numpy as np
import pytest

from gyrocal.calib.model import GyroCalibration
from gyrocal.kit.cli import main
from gyrocal.kit.config import MAX_SENSORS, load_config
from gyrocal.kit.errors import InputError
from gyrocal.kit.plate import RecordingGroup
from gyrocal.kit.recording import RecordingWriter, load_recording, read_manifest
from gyrocal.kit.sim import build_sim, build_sim_plate
from tests.calib.fullmodel_truth import truth_in_frame
from tests.kit.conftest import LOOP_50_HZ

PAPER_SENSOR = ("--sim-realism", "off")  # as tests/kit/test_calibrate.py: no realism effects

#: Three sensors of different models on one I²C bus, each at an address its model can have
#: (MPU-9250 and ICM-42688-P: 0x68/0x69; LSM6DSOX: 0x6A/0x6B; hardware reference §1-2).
THREE = """
[[imu]]
name = "mpu"
model = "mpu9250"
address = 0x68
[[imu]]
name = "icm"
model = "icm42688p"
address = 0x69
[[imu]]
name = "st"
model = "lsm6dsox"
address = 0x6A
odr_hz = 208.0
"""
TWO_BUSES = """
[[imu]]
name = "a"
model = "mpu9250"
address = 0x68
[[imu]]
name = "b"
model = "icm20948"
address = 0x68
bus = 3
odr_hz = 225.0
"""


#: The planner's diagonal protocol in 18 s of jig time (as tests/kit/test_reliability.py's
#: forced rerun): for the runs that check how a failing sensor is handled, not the estimate.
#: These and the three-sensor run loop at 50 Hz (:data:`tests.kit.conftest.LOOP_50_HZ`): what
#: they check (each sensor's own calibration, routing, one sensor failing alone) does not
#: depend on the loop rate.
SHORT = '[protocol]\nname = "auto"\ntime_budget_s = 18.0\n' + LOOP_50_HZ


def write(tmp_path, text, name="g.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


# ----------------------------------------------------------------------------- config
def test_imu_tables_list_the_sensors_and_a_single_imu_is_still_one_sensor(tmp_path):
    cfg = load_config(write(tmp_path, THREE + "[protocol]\nname = 'auto'\n"))
    assert [s["name"] for s in cfg.imus()] == ["mpu", "icm", "st"]
    assert [s["address"] for s in cfg.imus()] == [0x68, 0x69, 0x6A]
    assert cfg.imus()[1]["odr_hz"] == 200.0  # the [imu] default fills what a table leaves out
    assert cfg["imu"]["model"] == "mpu9250"  # the first sensor, for one-sensor readers
    single = load_config(write(tmp_path, "[imu]\nmodel = 'lsm9ds1'\naddress = 0x6B\n", "s.toml"))
    assert single.imus() == [{**single["imu"], "name": "imu"}]
    # same address on different buses is fine; unnamed sensors get model-bus-address
    two = load_config(write(tmp_path, TWO_BUSES.replace('name = "b"\n', ""), "t.toml"))
    assert [s["name"] for s in two.imus()] == ["a", "icm20948-3-68"]


@pytest.mark.parametrize(("text", "message"), [
    (THREE.replace("0x69", "0x68"), "sensors 'mpu' and 'icm' have the same I2C bus and address"),
    (THREE.replace('"icm"', '"MPU"'), "have the same name"),
    (THREE.replace('"st"', '"../x"'), "name '../x' must be 1-40 letters"),
    (THREE + "speed = 3\n", r"\[\[imu\]\] number 3: unknown key speed; allowed: name, model"),
    (THREE.replace('"lsm6dsox"', '"bmi160"'), "imu.model is 'bmi160'; allowed"),
    ("imu = [1, 2]\n", r"\[\[imu\]\] number 1 must be a table"),
    ("imu = []\n", "lists 0 sensors; give 1 to 8"),
    ("".join(f"[[imu]]\naddress = {0x10 + i}\n" for i in range(MAX_SENSORS + 1)),
     "lists 9 sensors; give 1 to 8"),
])
def test_bad_sensor_tables_are_refused_with_what_to_do(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        load_config(write(tmp_path, text))


def test_single_sensor_flags_are_refused_with_several_sensors(tmp_path, capsys):
    cfg = write(tmp_path, THREE)
    code = main(["calibrate", "--sim", "--config", str(cfg), "--imu-model", "lsm9ds1",
                 "--out", str(tmp_path / "o"), "--quiet", "--no-report"])
    assert code == 2
    assert "edit each [[imu]] table instead" in capsys.readouterr().err
    assert not (tmp_path / "o" / "mpu").exists()
    # commands that drive one sensor (verify, thermal, track --live) say so rather than use
    # the first silently: their shared Jig refuses a plate unless asked for several
    from gyrocal.kit.cli import build_parser
    from gyrocal.kit.jig import Jig

    args = build_parser().parse_args(["calibrate", "--sim", "--config", str(cfg)])
    with pytest.raises(InputError, match="this command drives one sensor, and the config lists 3"):
        Jig(load_config(cfg), args)


# ----------------------------------------------------------------------------- emulated plate
def test_emulated_plate_gives_each_sensor_its_own_truth_on_the_shared_buses(tmp_path):
    cfg = load_config(write(tmp_path, THREE))
    plate = build_sim_plate(cfg, seed=4, realism=())
    assert len(plate) == 3 and plate[0].plate == plate
    # the first sensor is the one-sensor --sim's, the others differ from it and each other
    one = build_sim(cfg, seed=4, realism=())
    assert np.array_equal(one.truth.scale, plate[0].truth.scale)
    scales = {tuple(p.truth.scale) for p in plate}
    mounts = {tuple(np.round(p.jig.mount_rotvec, 12)) for p in plate}
    assert len(scales) == 3 and len(mounts) == 3
    # one bus carries all three chips, each at its address; the servos and clock are shared
    assert plate[1].imu_bus is plate[0].imu_bus is plate[2].imu_bus
    assert {0x68, 0x69, 0x6A} <= set(plate[0].imu_bus.addresses)
    assert {id(p.servo_bus) for p in plate} == {id(plate[0].servo_bus)}
    # one gimbal: every sensor's joint axes are the same axes, seen through its own mount
    for p in plate[1:]:
        assert np.allclose(p.jig.axes, plate[0].jig.axes)
    two = build_sim_plate(load_config(write(tmp_path, TWO_BUSES, "t.toml")), seed=4)
    assert two[0].imu_bus is not two[1].imu_bus
    with pytest.raises(InputError, match="--sim-scale fixes one sensor's truth"):
        build_sim_plate(cfg, seed=4, scale=[1, 1, 1])


def test_recording_group_routes_rows_and_closes_a_failed_sensor(tmp_path):
    from gyrocal.calib.segments import Segment

    parts = {"sensor": {"model": "mpu9250"}, "gimbal": {"motors": []}, "protocol": {}}
    group = RecordingGroup([RecordingWriter(tmp_path / n, **parts) for n in "ab"])
    group.append_imus([(np.array([0.0, 0.005]), np.ones((2, 3)), None), None])
    group.append_encoder(0.0, [1], [0.5])
    group.fail(1, "stopped answering", 4)
    group.append_imus([(np.array([0.01]), np.ones((1, 3)), None),
                       (np.array([0.01]), np.ones((1, 3)), None)])
    group.append_segment(Segment(0, "rest", None, 0, 0.0, 0.0, 0.01))
    group.finish()
    a, b = read_manifest(tmp_path / "a"), read_manifest(tmp_path / "b")
    assert a["complete"] and "failure" not in a
    assert not b["complete"] and b["failure"] == {"message": "stopped answering", "exit_code": 4}
    assert len((tmp_path / "a" / "imu.csv").read_text().splitlines()) == 1 + 3
    assert len((tmp_path / "b" / "imu.csv").read_text().splitlines()) == 1  # header only
    assert len((tmp_path / "b" / "segments.csv").read_text().splitlines()) == 1


# ----------------------------------------------------------------------------- one run, many
#: The three-sensor run's rests at 0.5 s instead of the planner's 1 s: 30.7 s of jig time
#: instead of 44.6, the same posed full protocol. Seed 11, 1 s -> 0.5 s rests, each sensor's
#: worst matrix |err/sigma| and its bias err/sigma (the test: < 4):
#: mpu 1.31, 0.43 -0.51 0.31 -> 0.91, 0.43 0.83 0.02; icm 1.26, 0.36 0.11 -0.38 ->
#: 0.98, -0.35 0.61 0.54; st 1.79, -0.16 -0.50 0.21 -> 1.21, -0.96 0.37 0.03; every
#: calibration full and consistent at both.
SHORT_RESTS = "[protocol]\nrest_s = 0.5\n"


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    d = tmp_path_factory.mktemp("plate3")
    cfg = write(d, THREE + LOOP_50_HZ + SHORT_RESTS)
    out = d / "run"
    code = main(["calibrate", "--sim", "--sim-seed", "11", *PAPER_SENSOR, "--config", str(cfg),
                 "--out", str(out), "--quiet", "--no-report",
                 "--history", f"sqlite:///{d / 'history.sqlite'}",
                 "--sensor-label", "mpu=imu-01, icm=imu-02,st=imu-03"])
    return cfg, out, code


def test_three_sensors_of_different_models_are_each_calibrated_to_their_own_truth(three):
    cfg_path, out, code = three
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["passed"] and [s["verdict"] for s in summary["sensors"]] == ["passed"] * 3
    plate = build_sim_plate(load_config(cfg_path), seed=11, realism=())
    truths = []
    for k, name in enumerate(("mpu", "icm", "st")):
        rec = load_recording(out / name / "recording")
        assert rec.complete and rec.manifest["plate"]["sensor"] == name
        assert rec.sensor["model"] == ("mpu9250", "icm42688p", "lsm6dsox")[k]
        # the manifest's truth is this sensor's, as the emulated plate draws it
        truth = rec.truth
        assert np.allclose(truth["scale"], plate[k].truth.scale)
        assert np.allclose(truth["misalignment"], plate[k].truth.misalignment)
        truths.append(tuple(truth["scale"]))
        cal = GyroCalibration.from_json((out / name / "calibration.json").read_text())
        assert cal.is_full and cal.consistency.ok
        C = np.diag(1 / np.asarray(truth["scale"])) @ np.asarray(truth["misalignment"])
        std = np.sqrt(np.diag(cal.covariance_matrix))
        free = std[:9] > 0
        z = (cal.full_matrix - truth_in_frame(C)).ravel()[free] / std[:9][free]
        assert np.all(np.abs(z) < 4), (name, z)
        assert np.all(np.abs(np.asarray(cal.bias) - truth["bias"]) < 4 * std[9:]), name
        # every sensor saw every step: the same segments in each recording
        assert [s.t_start for s in rec.segments] == [
            s.t_start for s in load_recording(out / "mpu" / "recording").segments]
    assert len(set(truths)) == 3
    servos = json.loads((out / "sim-state.json").read_text())["servos"]
    assert all(s["torque_enable"] == 0 for s in servos.values())


def test_history_gets_one_record_per_sensor_under_its_own_label(three):
    from gyrocal.kit.history import open_history

    _, out, code = three
    assert code == 0
    with open_history(f"sqlite:///{out.parent / 'history.sqlite'}") as store:
        by_label = {r.label: r for r in store.records()}
    assert sorted(by_label) == ["imu-01", "imu-02", "imu-03"]
    for label, name in (("imu-01", "mpu"), ("imu-02", "icm"), ("imu-03", "st")):
        stored = GyroCalibration.from_json(by_label[label].document)
        written = GyroCalibration.from_json((out / name / "calibration.json").read_text())
        assert np.array_equal(stored.full_matrix, written.full_matrix)


@pytest.mark.parametrize(("label", "says"), [
    ("mpu=imu-01", "no label for icm, st"),
    ("mpu=a,icm=b,st=c,xx=d", "names 'xx', which is not on the plate"),
    ("mpu=a,mpu=b", "NAME=LABEL pairs"),
])
def test_plate_labels_are_checked_before_the_jig_moves(tmp_path, capsys, label, says):
    out = tmp_path / "o"
    code = main(["calibrate", "--sim", "--config", str(write(tmp_path, THREE)), "--out",
                 str(out), "--quiet", "--no-report", "--history",
                 f"sqlite:///{tmp_path / 'h.sqlite'}", "--sensor-label", label])
    assert code == 2
    assert says in capsys.readouterr().err
    assert not (out / "mpu").exists()


def test_one_plain_label_labels_each_sensor_by_its_place():
    from gyrocal.kit.plate import sensor_labels

    assert sensor_labels("batch-12", ["top", "bottom"]) == ["batch-12/top", "batch-12/bottom"]


def test_a_sensor_that_dies_mid_run_fails_alone(tmp_path, capsys):
    cfg = write(tmp_path, TWO_BUSES + SHORT)
    out = tmp_path / "run"
    code = main(["calibrate", "--sim", "--sim-seed", "2", *PAPER_SENSOR,
                 "--config", str(cfg), "--out", str(out), "--quiet", "--no-report",
                 "--sim-fault", "imu-dead:6@b"])
    text = capsys.readouterr().out
    assert code == 4  # the dead sensor's class: hardware
    assert "== sensor a: mpu9250 at 0x68 on bus 1: PASSED" in text
    assert "== sensor b: icm20948 at 0x68 on bus 3: FAILED: failed during the run: stopped " \
           "answering" in text
    assert "plate: 1 of 2 sensors passed" in text
    summary = json.loads((out / "summary.json").read_text())
    assert [s["exit_code"] for s in summary["sensors"]] == [0, 4]
    assert (out / "a" / "calibration.json").exists()
    assert not (out / "b" / "calibration.json").exists()
    b = load_recording(out / "b" / "recording")
    assert not b.complete and b.imu_t[-1] < 6.0 + 0.1  # kept up to its death, marked
    servos = json.loads((out / "sim-state.json").read_text())["servos"]
    assert all(s["torque_enable"] == 0 for s in servos.values())


def test_a_sensor_whose_fifo_overflows_on_every_repeat_fails_alone(tmp_path, capsys):
    # a FIFO of one sample (14 bytes, as tests/kit/test_calibrate.py) on sensor b only
    cfg = write(tmp_path, '[[imu]]\nname = "mpu"\naddress = 0x68\n'
                          '[[imu]]\nname = "b"\naddress = 0x69\n' + SHORT)
    out = tmp_path / "run"
    code = main(["calibrate", "--sim", *PAPER_SENSOR, "--config", str(cfg), "--out", str(out),
                 "--quiet", "--no-report", "--sim-fault", "fifo:14@b"])
    text = capsys.readouterr().out
    assert code == 5  # a check's class
    assert "== sensor mpu: mpu9250 at 0x68 on bus 1: PASSED" in text
    assert "gyro samples were lost" in text and "(on 4 attempts)" in text
    manifest = read_manifest(out / "b" / "recording")
    assert manifest["failure"]["exit_code"] == 5 and not manifest["complete"]
    # the repeats are listed, naming the sensor, in the recordings that go on
    discarded = read_manifest(out / "mpu" / "recording")["protocol"]["discarded"]
    assert [d["check"] for d in discarded] == ["fifo-gap"] * 4
    assert load_recording(out / "mpu" / "recording").complete


def test_when_every_sensor_dies_the_run_stops_with_torque_off(tmp_path, capsys):
    cfg = write(tmp_path, TWO_BUSES)
    out = tmp_path / "run"
    code = main(["calibrate", "--sim", *PAPER_SENSOR, "--protocol", "auto", "--config",
                 str(cfg), "--out", str(out), "--quiet", "--no-report",
                 "--sim-fault", "imu-dead:3@a", "--sim-fault", "imu-dead:4@b"])
    assert code == 4
    assert "every sensor on the plate failed" in capsys.readouterr().err
    servos = json.loads((out / "sim-state.json").read_text())["servos"]
    assert all(s["torque_enable"] == 0 for s in servos.values())


def test_a_fault_for_an_unknown_sensor_is_bad_usage(tmp_path, capsys):
    code = main(["calibrate", "--sim", "--config", str(write(tmp_path, TWO_BUSES)), "--out",
                 str(tmp_path / "o"), "--quiet", "--sim-fault", "imu-dead:3@c"])
    assert code == 2
    assert "no sensor named 'c'; the sensors are a, b" in capsys.readouterr().err
