"""The vectorised decimal parser (issue 16) against Python's ``float`` of the same text.

The texts are made here from the grammar (random digits, points, signs, exponents), not by
gyrocal's writer; every value must equal ``float(text)`` bit for bit (sign of zero included).
"""

import numpy as np
import pytest

from gyrocal.kit import decimal_csv
from gyrocal.kit.decimal_csv import parse_plain_decimal


def _random_field(rng):
    kind = rng.integers(7)
    digits = "".join(rng.choice(list("0123456789"), rng.integers(1, 16)))
    sign = "-" if rng.random() < 0.5 else ""
    if kind == 0:
        return f"{rng.normal() * 10.0 ** rng.integers(-8, 8):.{rng.integers(0, 12)}f}"
    if kind == 1:
        return f"{rng.normal() * 10.0 ** rng.integers(-30, 30):.{rng.integers(1, 11)}g}"
    if kind == 2:
        return sign + digits
    if kind == 3:
        cut = rng.integers(0, len(digits) + 1)
        return sign + digits[:cut] + "." + digits[cut:]
    if kind == 4:  # beyond 2**53 or 16 bytes: float()'s exact conversion
        return sign + "".join(rng.choice(list("123456789"), rng.integers(16, 19)))
    if kind == 5:
        return f"{rng.normal():.{rng.integers(0, 12)}e}".replace("e", rng.choice(["e", "E"]))
    return repr(float(rng.normal() * 10.0 ** rng.integers(-5, 5)))


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("piece", [64, 1 << 19], ids=["tiny-pieces", "default-pieces"])
def test_random_fields_equal_pythons_float_bit_for_bit(monkeypatch, piece):
    monkeypatch.setattr(decimal_csv, "PIECE_BYTES", piece)
    monkeypatch.setattr(decimal_csv, "MAX_SPECIAL", 1.0)  # exercise float()'s share too
    rng = np.random.default_rng(11)
    for _ in range(40):
        rows = [[_random_field(rng) for _ in range(5)] for _ in range(60)]
        text = "".join(",".join(r) + "\n" for r in rows).encode()
        got = parse_plain_decimal(text, 5)
        truth = np.array([[float(f) for f in r] for r in rows])
        assert got is not None
        np.testing.assert_array_equal(_bits(got), _bits(truth))


EDGES = ["0", "-0", "-0.0", "0.", ".0", "5.", ".5", "-.5", "007.50", "0.1", "0.3",
         "9007199254740992", "9007199254740993", "-9007199254740993", "1234567890123456",
         "123456789012345.6", "0.000000000000001", "999999999999999.9", "4503599627370497.5",
         "1e22", "1e23", "2.2250738585072014e-308", "1E+5", "1e-5", "12345678901234567890"]


def test_edge_cases_equal_pythons_float(monkeypatch):
    monkeypatch.setattr(decimal_csv, "MAX_SPECIAL", 1.0)
    text = "".join(f"{f},1\n" for f in EDGES).encode()
    got = parse_plain_decimal(text, 2)
    np.testing.assert_array_equal(_bits(got[:, 0]), _bits([float(f) for f in EDGES]))
    assert np.signbit(got[EDGES.index("-0.0"), 0])


@pytest.mark.parametrize("field", ["", "-", ".", "-.", "1.2.3", "1-2", "--1", "e5", "1e",
                                   "1e+-5", " 1", "1 ", "inf", "nan", "0x10", "1_0", "#1",
                                   "1.5e1.5", "+-1", "1\r"])
def test_anything_else_is_left_to_the_caller(field):
    assert parse_plain_decimal(f"1,2\n{field},3\n4,5\n".encode(), 2) is None


def test_only_the_empty_column_may_be_empty_and_reads_nan():
    got = parse_plain_decimal(b"1,,3\n-4,,6.5\n", 3, empty_col=1)
    assert np.isnan(got[:, 1]).all()
    np.testing.assert_array_equal(got[:, [0, 2]], [[1, 3], [-4, 6.5]])
    assert parse_plain_decimal(b"1,,3\n", 3, empty_col=2) is None
    assert parse_plain_decimal(b"1,2,\n", 3) is None


@pytest.mark.parametrize("text", [b"1,2\n3\n", b"1,2,3\n4,5\n", b"1\n2,3\n", b"1,2",
                                  b"1,2\n\n"])
def test_a_line_with_the_wrong_field_count_or_no_newline_is_refused(text):
    assert parse_plain_decimal(text, 2) is None


def test_many_exponents_go_to_the_caller_rather_than_float_one_by_one():
    rows = "".join(f"{v:.6e},{v:.6e}\n" for v in np.linspace(1, 2, 100)).encode()
    assert parse_plain_decimal(rows, 2) is None  # more than MAX_SPECIAL of the fields
    assert parse_plain_decimal(b"", 2).shape == (0, 2)
