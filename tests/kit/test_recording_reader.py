"""The block reader of Recording v1 (issue 16) and its input bounds (issue 17).

The files here are written by hand from the contract (Python's own float formatting, CRLF,
spaces), not by RecordingWriter, and every value is checked against Python's ``float`` of the
text: an independent truth for numpy's C parser and the exact fallback.
"""

import json
import os
import subprocess
import sys
import time
import tracemalloc

import numpy as np
import pytest

from gyrocal.kit import recording
from gyrocal.kit.errors import InputError
from gyrocal.kit.recording import RecordingError, iter_imu, load_recording

MANIFEST = {"format": "gyrocal-recording", "version": 1, "created": "2026-01-01T00:00:00+00:00",
            "sensor": {"model": "x"}, "gimbal": {}, "protocol": {}, "complete": True}


def make_rows(n, seed=0, *, empty_temp_every=7):
    """IMU rows as text with Python's repr floats (a third-party writer), and their values."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.001, 0.01, n))
    rate = rng.normal(scale=[1e-3, 1.0, 300.0], size=(n, 3))
    temp = rng.uniform(-40, 85, n)
    temp[::empty_temp_every] = np.nan
    lines = []
    for i in range(n):
        # mostly as gyrocal writes them (fixed and %g, exponents included), one row in ten as
        # Python's repr (17 significant digits), so the vectorised decimal parser reads most
        # fields and hands the rest to float()
        if i % 10 == 3:
            tt = "" if np.isnan(temp[i]) else repr(float(temp[i]))
            fields = [repr(float(t[i])), *(repr(float(v)) for v in rate[i]), tt]
        else:
            tt = "" if np.isnan(temp[i]) else f"{temp[i]:.4f}"
            fields = [f"{t[i]:.9f}", *(f"{v:.10g}" for v in rate[i]), tt]
        lines.append(",".join(fields))
    vals = np.array([[float(f) if f else np.nan for f in x.split(",")] for x in lines])
    return lines, vals[:, 0], vals[:, 1:4], vals[:, 4]


def write_rec(root, imu_lines, *, enc_lines=("0.0,1,0.0", "0.5,1,0.25"), eol="\n",
              seg_lines=("0,rest,,0,0,0.0,0.5",)):
    root.mkdir(exist_ok=True)
    (root / "manifest.json").write_text(json.dumps(MANIFEST))
    (root / "imu.csv").write_bytes(("t,gx,gy,gz,temp" + eol + "".join(
        line + eol for line in imu_lines)).encode())
    (root / "encoder.csv").write_text("t,motor,angle\n" + "".join(f"{x}\n" for x in enc_lines))
    (root / "segments.csv").write_text(
        "index,kind,motor,direction,speed,t_start,t_end\n" + "".join(f"{x}\n" for x in seg_lines))
    return root


@pytest.fixture(
    params=[(200, "decimal"), (1 << 22, "decimal"), (200, "numpy"), (1 << 22, "numpy"),
            (200, "pandas"), (1 << 22, "pandas")],
    ids=["tiny-blocks", "default-blocks", "tiny-blocks-loadtxt", "default-blocks-loadtxt",
         "tiny-blocks-pandas", "default-blocks-pandas"],
)
def block_bytes(request, monkeypatch):
    """Every reader test on small and default blocks, through the vectorised decimal parser
    (the default without pandas), numpy.loadtxt and (with the ``fast`` extra) pandas' C
    parser."""
    size, parser = request.param
    if parser == "pandas":
        pytest.importorskip("pandas")
    monkeypatch.setattr(recording, "BLOCK_BYTES", size)
    monkeypatch.setenv("GYROCAL_CSV_PARSER", parser)
    return size


@pytest.mark.parametrize("eol", ["\n", "\r\n"])
def test_values_equal_pythons_float_of_the_text(tmp_path, block_bytes, eol):
    lines, t, rate, temp = make_rows(500)
    lines[3] = " " + lines[3].replace(",", " , ")  # spaces around fields are allowed
    write_rec(tmp_path / "r", lines, eol=eol)
    rec = load_recording(tmp_path / "r")
    truth = np.array([[float(f) if f.strip() else np.nan for f in x.split(",")] for x in lines])
    np.testing.assert_array_equal(rec.imu_t, truth[:, 0])
    np.testing.assert_array_equal(rec.imu_rate, truth[:, 1:4])
    np.testing.assert_array_equal(rec.imu_temp, truth[:, 4])  # NaN where the field is empty
    assert rec.imu_rate.flags.c_contiguous and rec.imu_t.flags.c_contiguous
    np.testing.assert_array_equal(rec.enc_motor, [1, 1])
    assert rec.enc_motor.dtype == np.int64 and rec.warnings == ()
    # the stream gives the same samples, block by block
    got = list(iter_imu(tmp_path / "r"))
    if block_bytes == 200:
        assert len(got) > 10
    np.testing.assert_array_equal(np.concatenate([g[1] for g in got]), truth[:, 1:4])
    np.testing.assert_array_equal(np.concatenate([g[2] for g in got]), truth[:, 4])


@pytest.mark.parametrize("row, message", [
    ("{t},abc,0,0,", r"imu.csv:{line}: field 2 is 'abc', not a number"),
    ("{t},1,2", r"imu.csv:{line}: expected 5 comma-separated fields, got 3"),
    ("{t},1,2,3,4,5", r"imu.csv:{line}: expected 5 comma-separated fields, got 6"),
    ("", r"imu.csv:{line}: expected 5 comma-separated fields, got 1"),  # a blank line
    ("{t},1,,3,", r"imu.csv:{line}: field 3 is '', not a number"),
    ("{t},inf,0,0,", r"imu.csv:{line}: field 2 is 'inf'"),
    ("nan,0,0,0,", r"imu.csv:{line}: field 1 is 'nan'"),
    ("{t},0,0,0,inf", r"imu.csv:{line}: field 5 is 'inf'"),
    ("{t},0x10,0,0,", r"imu.csv:{line}: field 2 is '0x10', not a number"),
    ("#{t},0,0,0,", r"imu.csv:{line}: field 1 is '#"),
])
@pytest.mark.parametrize("where", [5, 400])
def test_a_bad_row_is_named_by_file_and_line(tmp_path, block_bytes, row, message, where):
    lines, t, *_ = make_rows(500)
    lines[where] = row.format(t=repr(float(t[where])))
    write_rec(tmp_path / "r", lines)
    with pytest.raises(RecordingError, match=message.format(line=where + 2)):
        load_recording(tmp_path / "r")
    with pytest.raises(RecordingError, match=message.format(line=where + 2)):
        list(iter_imu(tmp_path / "r"))  # the streaming reader (noise, track) names it alike


@pytest.mark.parametrize("where", [1, 250, 499])
def test_time_going_backwards_is_refused_at_its_line(tmp_path, block_bytes, where):
    lines, t, *_ = make_rows(500)
    lines[where] = ",".join([repr(float(t[where - 1]) - 1e-6), *lines[where].split(",")[1:]])
    write_rec(tmp_path / "r", lines)
    with pytest.raises(RecordingError, match=rf"imu.csv:{where + 2}: time goes backwards"):
        load_recording(tmp_path / "r")
    with pytest.raises(RecordingError, match=rf"imu.csv:{where + 2}: time goes backwards"):
        list(iter_imu(tmp_path / "r"))


def test_equal_times_are_allowed(tmp_path):
    write_rec(tmp_path / "r", ["0.0,0,0,0,", "0.0,1,1,1,"], enc_lines=["0.0,1,0", "0.0,2,0"])
    assert load_recording(tmp_path / "r").imu_t.tolist() == [0.0, 0.0]


def test_a_partial_last_row_is_dropped_with_a_short_warning(tmp_path, block_bytes):
    lines, t, *_ = make_rows(300)
    write_rec(tmp_path / "r", lines)
    with open(tmp_path / "r" / "imu.csv", "a") as fh:
        fh.write("9999.5," + "1" * 3000)  # no newline: the run stopped mid-row
    rec = load_recording(tmp_path / "r")
    assert rec.imu_t.size == 300 and rec.imu_t[-1] == float(lines[-1].split(",")[0])
    (w,) = rec.warnings
    assert "imu.csv: dropped a partial last row '9999.5,111" in w and len(w) < 150
    warns = []
    assert sum(b[0].size for b in iter_imu(tmp_path / "r", warns)) == 300 and warns == [w]


def test_header_only_and_empty_files(tmp_path):
    write_rec(tmp_path / "r", [], enc_lines=())
    rec = load_recording(tmp_path / "r")
    assert rec.imu_t.shape == (0,) and rec.imu_rate.shape == (0, 3) and rec.enc_t.size == 0
    (tmp_path / "r" / "imu.csv").write_text("")
    with pytest.raises(RecordingError, match="imu.csv is empty: expected the header"):
        load_recording(tmp_path / "r")
    (tmp_path / "r" / "imu.csv").write_text("t,gx,gy,gz\n")
    with pytest.raises(RecordingError, match="header is 't,gx,gy,gz', expected"):
        load_recording(tmp_path / "r")


def test_nul_bytes_are_refused_quickly_with_the_line(tmp_path):
    lines, *_ = make_rows(100)
    write_rec(tmp_path / "r", lines)
    imu = tmp_path / "r" / "imu.csv"
    size = imu.stat().st_size
    with open(imu, "r+b") as fh:  # a 1 GB run of zeros after the rows (sparse: costs no disk)
        fh.truncate(size + (1 << 30))
    t0 = time.process_time()
    with pytest.raises(RecordingError, match=r"imu.csv:102: NUL bytes .* cut the file"):
        load_recording(tmp_path / "r")
    assert time.process_time() - t0 < 5  # one block is read, not the gigabyte


def test_an_overlong_line_is_refused(tmp_path, block_bytes):
    lines, *_ = make_rows(50)
    lines[20] = "1" * (recording.MAX_LINE_BYTES + 10)
    write_rec(tmp_path / "r", lines)
    with pytest.raises(RecordingError, match=r"imu.csv:22: line longer than 4096 bytes") as exc:
        load_recording(tmp_path / "r")
    assert len(str(exc.value)) < 300


def test_files_over_their_size_cap_are_refused(tmp_path, monkeypatch):
    lines, *_ = make_rows(50)
    write_rec(tmp_path / "r", lines)
    monkeypatch.setattr(recording, "MAX_CSV_BYTES", 1000)
    with pytest.raises(RecordingError, match=r"imu.csv is \d+ bytes, more than the 1000"):
        load_recording(tmp_path / "r")
    monkeypatch.setattr(recording, "MAX_CSV_BYTES", 1 << 20)
    (tmp_path / "r" / "manifest.json").write_text(" " * (recording.MAX_MANIFEST_BYTES + 1))
    with pytest.raises(RecordingError, match=r"manifest.json is \d+ bytes, more than"):
        load_recording(tmp_path / "r")


NAMES = ["imu.csv", "encoder.csv", "segments.csv", "manifest.json"]
KINDS = ["directory", "symlink-to-directory", "dev-zero", "fifo"]

#: The child process that reads each recording of :func:`irregular_reads` in turn: its exit
#: code (2 on a RecordingError, 1 on any other exception, 0 if it read) and message per case.
READ_EACH = """import json, sys
from gyrocal.kit.recording import load_recording, RecordingError
out = {}
for case, root in json.loads(sys.argv[1]).items():
    try:
        load_recording(root)
        out[case] = [0, ""]
    except RecordingError as e:
        out[case] = [2, str(e)]
    except Exception as e:
        out[case] = [1, repr(e)]
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def irregular_reads(tmp_path_factory):
    """``"kind/name" -> (exit code, message)`` of reading a recording whose file ``name`` is
    not a regular file but ``kind``, every case read in one child process with a timeout: a
    reader that blocked on a FIFO or read /dev/zero for ever fails the tests instead of hanging
    them (one interpreter start for the 16 cases instead of one each)."""
    roots = {}
    for kind in KINDS:
        for name in NAMES:
            d = tmp_path_factory.mktemp("irregular")
            root = write_rec(d / "r", make_rows(10)[0])
            target = root / name
            target.unlink()
            if kind == "directory":
                target.mkdir()
            elif kind == "symlink-to-directory":
                target.symlink_to(d)
            elif kind == "dev-zero":
                target.symlink_to("/dev/zero")
            else:
                os.mkfifo(target)
            roots[f"{kind}/{name}"] = str(root)
    out = subprocess.run([sys.executable, "-c", READ_EACH, json.dumps(roots)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("kind", KINDS)
def test_only_regular_files_are_read(irregular_reads, name, kind):
    code, message = irregular_reads[f"{kind}/{name}"]
    assert code == 2, message
    want = {"directory": "is a directory", "symlink-to-directory": "is a directory",
            "dev-zero": "is a character device", "fifo": "is a named pipe (FIFO)"}[kind]
    assert f"{name} {want}: a recording's files must be regular files" in message


def test_damaged_manifest_messages_stay_short(tmp_path):
    root = write_rec(tmp_path / "r", [])
    (root / "manifest.json").write_text("[" * 100000)
    with pytest.raises(RecordingError, match="not valid JSON"):
        load_recording(root)
    doc = dict(MANIFEST, version=int("9" * 4000))
    (root / "manifest.json").write_text(json.dumps(doc) if sys.get_int_max_str_digits() == 0
                                        else json.dumps(dict(MANIFEST, version="9" * 4000)))
    with pytest.raises(RecordingError, match="is not supported") as exc:
        load_recording(root)
    assert len(str(exc.value)) < 300
    (root / "manifest.json").write_bytes(b'{"format": "\xff"}')
    with pytest.raises(RecordingError, match="not valid JSON"):
        load_recording(root)


def test_reader_memory_does_not_grow_with_rows_beyond_the_arrays(tmp_path, monkeypatch):
    # No per-row Python objects: what the reader allocates beyond its float64 arrays is one
    # block's worth, the same for 20 000 rows as for 200 000 (the old reader held ~430 B/row).
    monkeypatch.setattr(recording, "BLOCK_BYTES", 1 << 16)
    base = "{:.9f},0.001234567891,-0.002345678912,0.0003456789123,25.1250\n"
    extra = []
    for n in (20_000, 200_000):
        root = write_rec(tmp_path / f"r{n}", [])
        with open(root / "imu.csv", "a") as fh:
            fh.write("".join(base.format(i * 1e-3) for i in range(n)))
        tracemalloc.start()
        rec = load_recording(root)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        arrays = sum(a.nbytes for a in (rec.imu_t, rec.imu_rate, rec.imu_temp))
        extra.append(peak - arrays)
        del rec
    assert extra[1] < 2e6 and extra[1] - extra[0] < 0.2e6, extra


ODD_FIELDS = ["1_000", "0x10", " 1.5", "1.5 ", "+1", "1e5", "1.", ".", "-", "1d5", "1.5.3", "inf",
              "-Infinity", "nan", "NaN", "NA", "null", "'1'", '"1"', "1e400", "1e-400", "\u0661",
              "1.5\t", "", "#1", "1#"]


@pytest.mark.parametrize("parser", ["decimal", "numpy", "pandas"])
@pytest.mark.parametrize("column", [1, 4], ids=["gx", "temp"])
@pytest.mark.parametrize("field", ODD_FIELDS)
def test_a_fast_parser_accepts_exactly_what_python_float_accepts(tmp_path, monkeypatch, parser,
                                                                column, field):
    """The truth is the contract read with Python's float(): a field is a number if it is ASCII
    (the files are), has no underscore (float() reads "1_0.5" as 10.5, a digit group no CSV
    writer means), and float() of it, stripped, is finite; an empty or NaN field is allowed
    only as the temperature."""
    if parser == "pandas":
        pytest.importorskip("pandas")
    monkeypatch.setenv("GYROCAL_CSV_PARSER", parser)
    lines, *_ = make_rows(20, empty_temp_every=1000)
    row = lines[10].split(",")
    row[column] = field
    lines[10] = ",".join(row)
    write_rec(tmp_path / "r", lines)
    try:
        v = float(field.strip()) if field.strip() else float("nan")
        ok = field.isascii() and "_" not in field and (np.isfinite(v)
                                                       or (column == 4 and np.isnan(v)))
    except ValueError:
        ok = False
    if ok:
        rec = load_recording(tmp_path / "r")
        got = rec.imu_temp[10] if column == 4 else rec.imu_rate[10, 0]
        np.testing.assert_array_equal(got, v)
    else:
        with pytest.raises(RecordingError, match=rf"imu.csv:12: field {column + 1} is"):
            load_recording(tmp_path / "r")


def test_the_parser_choice(monkeypatch):
    """auto: the vectorised decimal parser, whether pandas is installed or not; the others
    when asked for by name."""
    monkeypatch.delenv("GYROCAL_CSV_PARSER", raising=False)
    assert recording._choose_parser() is recording._decimal_parse
    monkeypatch.setenv("GYROCAL_CSV_PARSER", "numpy")
    assert recording._choose_parser() is recording._numpy_parse
    monkeypatch.setenv("GYROCAL_CSV_PARSER", "fastest")
    with pytest.raises(InputError, match="GYROCAL_CSV_PARSER is 'fastest'; use auto, decimal, "
                                         "numpy or pandas"):
        recording._choose_parser()


def test_gyrocal_style_files_never_reach_loadtxt(tmp_path, monkeypatch):
    """Rows as gyrocal writes them (``%.9f``, ``%.10g`` with its exponents, ``%.4f``, an empty
    temperature) are read by the vectorised parser alone, every value equal to float()."""
    def refuse(*_):
        raise AssertionError("numpy.loadtxt was called")

    monkeypatch.setattr(recording, "_numpy_parse", refuse)
    monkeypatch.setenv("GYROCAL_CSV_PARSER", "decimal")
    monkeypatch.setattr(recording, "BLOCK_BYTES", 1 << 14)
    rng = np.random.default_rng(7)
    n = 3000
    t = np.cumsum(rng.uniform(0.0005, 0.002, n)) + 3000.0
    rate = rng.normal(scale=[2e-4, 0.5, 30.0], size=(n, 3))
    lines = [",".join([f"{t[i]:.9f}", *(f"{v:.10g}" for v in rate[i]),
                       "" if i % 5 == 0 else f"{20 + i * 1e-3:.4f}"]) for i in range(n)]
    assert sum("e" in x for x in lines) > 50  # %g's exponents are in the test
    write_rec(tmp_path / "r", lines)
    rec = load_recording(tmp_path / "r")
    truth = np.array([[float(f) if f else np.nan for f in x.split(",")] for x in lines])
    np.testing.assert_array_equal(np.column_stack([rec.imu_t, rec.imu_rate, rec.imu_temp]),
                                  truth)


def _with_accel(lines, rng):
    """``lines`` with the accelerometer's three columns (numbers: only ``temp`` may be empty),
    which the gyro stream must check and leave out."""
    return [line + "," + ",".join(repr(float(v)) for v in rng.normal(scale=9.8, size=3))
            for line in lines]


def test_the_stream_reads_past_the_accelerometer_columns(tmp_path, block_bytes):
    lines, t, rate, temp = make_rows(400, seed=3)
    write_rec(tmp_path / "r", _with_accel(lines, np.random.default_rng(4)))
    path = tmp_path / "r" / "imu.csv"
    path.write_text(path.read_text().replace("t,gx,gy,gz,temp\n", "t,gx,gy,gz,temp,ax,ay,az\n"))
    warns = []
    got = list(iter_imu(tmp_path / "r", warns))
    truth = np.array([[float(f) if f.strip() else np.nan for f in x.split(",")] for x in lines])
    np.testing.assert_array_equal(np.concatenate([g[0] for g in got]), truth[:, 0])
    np.testing.assert_array_equal(np.concatenate([g[1] for g in got]), truth[:, 1:4])
    np.testing.assert_array_equal(np.concatenate([g[2] for g in got]), truth[:, 4])
    assert warns == []
    # the extra columns are checked all the same: a bad field, a missing field, an empty gyro
    for bad, message in (("{t},1,2,3,4,5,x,6", "field 7 is 'x', not a number"),
                         ("{t},1,2,3,4,5,6", "expected 8 comma-separated fields, got 7"),
                         ("{t},1,,3,4,5,6,7", "field 3 is '', not a number"),
                         ("{t},1,2,3,4,5,6,inf", "field 8 is 'inf'")):
        text = path.read_text().split("\n")
        text[150] = bad.format(t=repr(float(t[148])))
        path.write_text("\n".join(text))
        with pytest.raises(RecordingError, match=f"imu.csv:151: {message}"):
            list(iter_imu(tmp_path / "r"))
    # a header that renames a gyro column is still refused
    path.write_text("t,gx,gy,gq,temp,ax\n" + "\n".join(text[1:]))
    with pytest.raises(RecordingError, match="header is"):
        list(iter_imu(tmp_path / "r"))
