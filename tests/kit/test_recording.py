import json

import numpy as np
import pytest

from gyrocal.calib.segments import Segment
from gyrocal.kit.errors import OutputExistsError
from gyrocal.kit.recording import RecordingError, RecordingWriter, load_recording

SENSOR = {"model": "mpu9250", "odr_hz": 200.0, "full_scale_dps": 500,
          "sensitivity_rad_s_per_lsb": 0.0002664624812}
GIMBAL = {"motors": [{"id": 1, "model": "XM430-W350", "axis": "x"}]}


def write_small(path, finish=True):
    rng = np.random.default_rng(0)
    t = np.arange(20) / 200.0
    rate = rng.normal(size=(20, 3))
    temp = np.full(20, 24.25)
    temp[3] = np.nan
    with RecordingWriter(path, sensor=SENSOR, gimbal=GIMBAL, protocol={"name": "test"},
                         truth={"scale": [1, 1, 1], "bias": [0, 0, 0]}) as w:
        w.append_imu(t[:10], rate[:10], temp[:10])
        w.append_imu(t[10:], rate[10:], temp[10:])
        w.append_encoder(0.0, [1, 2], [0.0, 1.5])
        w.append_encoder(np.array([0.05, 0.05]), [1, 2], [0.1, 1.5])
        w.append_segment(Segment(0, "rest", None, 0, 0.0, 0.0, 0.02))
        w.append_segment(Segment(1, "rotate", 1, -1, 2.0, 0.02, 0.1))
        if finish:
            w.finish()
    return t, rate, temp


def test_round_trip(tmp_path):
    t, rate, temp = write_small(tmp_path / "rec")
    rec = load_recording(tmp_path / "rec")
    assert rec.complete and rec.warnings == ()
    np.testing.assert_allclose(rec.imu_t, t, atol=1e-9)
    np.testing.assert_allclose(rec.imu_rate, rate, rtol=1e-9)
    assert np.isnan(rec.imu_temp[3]) and rec.imu_temp[0] == 24.25
    np.testing.assert_array_equal(rec.enc_motor, [1, 2, 1, 2])
    assert rec.encoder(2)[1].tolist() == [1.5, 1.5]
    assert rec.segments[1] == Segment(1, "rotate", 1, -1, 2.0, 0.02, 0.1)
    assert rec.truth == {"scale": [1, 1, 1], "bias": [0, 0, 0]}
    assert rec.sensor["model"] == "mpu9250"


def test_interrupted_run_stays_readable_and_incomplete(tmp_path):
    write_small(tmp_path / "rec", finish=False)
    rec = load_recording(tmp_path / "rec")
    assert not rec.complete
    # A crash mid-row leaves a partial last line: dropped with a warning, the rest kept.
    with open(tmp_path / "rec" / "imu.csv", "a") as fh:
        fh.write("0.1000,0.5,0.2")
    rec = load_recording(tmp_path / "rec")
    assert rec.imu_t.size == 20
    assert any("partial last row" in w for w in rec.warnings)


def test_refuses_to_overwrite(tmp_path):
    write_small(tmp_path / "rec")
    with pytest.raises(OutputExistsError, match="--force"):
        RecordingWriter(tmp_path / "rec", sensor=SENSOR, gimbal=GIMBAL, protocol={})
    assert load_recording(tmp_path / "rec").complete  # untouched


@pytest.mark.parametrize("missing", ["imu.csv", "encoder.csv", "segments.csv", "manifest.json"])
def test_missing_file_is_named(tmp_path, missing):
    write_small(tmp_path / "rec")
    (tmp_path / "rec" / missing).unlink()
    with pytest.raises(RecordingError, match=f"{missing} is missing"):
        load_recording(tmp_path / "rec")


def test_bad_contents_are_reported_with_file_and_line(tmp_path):
    write_small(tmp_path / "rec")
    p = tmp_path / "rec" / "imu.csv"
    lines = p.read_text().split("\n")
    lines[4] = "0.015,abc,0,0,"
    p.write_text("\n".join(lines))
    with pytest.raises(RecordingError, match=r"imu.csv:5: field 2 is 'abc', not a number"):
        load_recording(tmp_path / "rec")
    lines[4] = "0.015,1,2"
    p.write_text("\n".join(lines))
    with pytest.raises(RecordingError, match=r"imu.csv:5: expected 5 comma-separated fields"):
        load_recording(tmp_path / "rec")


def test_header_version_and_time_order_are_checked(tmp_path):
    write_small(tmp_path / "rec")
    enc = tmp_path / "rec" / "encoder.csv"
    enc.write_text("time,id,angle\n")
    with pytest.raises(RecordingError, match="header"):
        load_recording(tmp_path / "rec")
    enc.write_text("t,motor,angle\n1.0,1,0.0\n0.5,1,0.1\n")
    with pytest.raises(RecordingError, match="time goes backwards"):
        load_recording(tmp_path / "rec")
    m = tmp_path / "rec" / "manifest.json"
    doc = json.loads(m.read_text())
    doc["version"] = 7
    m.write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match="version 7 is not supported"):
        load_recording(tmp_path / "rec")


def test_not_a_directory(tmp_path):
    with pytest.raises(RecordingError, match="not a directory"):
        load_recording(tmp_path / "nothing")
