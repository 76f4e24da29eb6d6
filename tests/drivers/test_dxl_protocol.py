"""Protocol 2.0 framing of the emulator against the e-manual's examples and dynamixel-sdk."""

import numpy as np
import pytest
from dynamixel_sdk import PacketHandler

from gyrocal.drivers.emulated.dxl.protocol import (
    Instruction,
    InstructionParser,
    crc16,
    instruction_packet,
    remove_stuffing,
    status_packet,
    stuff,
)

SDK = PacketHandler(2.0)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# Complete packets from the Protocol 2.0 e-manual (hardware reference §4.2, "SDK CRCs equal every
# e-manual example"): (packet, what it is).
EMANUAL_PACKETS = [
    ("FF FF FD 00 01 03 00 01 19 4E", "PING ID 1"),
    ("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D", "PING status: model 1030, firmware 0x26"),
    ("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15", "READ ID 1, address 132, 4 bytes"),
    ("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0", "READ status: 166"),
    ("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89", "WRITE ID 1, address 116, 512"),
    ("FF FF FD 00 FE 03 00 01 31 42", "broadcast PING"),
    ("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA", "SYNC_READ 132+4 of IDs 1 and 2"),
    ("FF FF FD 00 01 03 00 08 2F 4E", "REBOOT ID 1"),
    ("FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC", "CLEAR ID 1"),
]


def test_crc_check_value_of_the_buypass_parameters():
    # poly 0x8005, init 0, no reflection, no final XOR: check("123456789") = 0xFEE8 (§4.2)
    assert crc16(b"123456789") == 0xFEE8


@pytest.mark.parametrize(("packet", "what"), EMANUAL_PACKETS)
def test_crc_of_every_emanual_example(packet, what):
    data = h(packet)
    expected = data[-2] | data[-1] << 8
    assert crc16(data[:-2]) == expected, what
    assert SDK.updateCRC(0, list(data), len(data) - 2) == expected, what


def test_emulator_frames_the_emanual_examples_byte_for_byte():
    assert status_packet(1, 0, h("06 04 26")) == h(EMANUAL_PACKETS[1][0])
    assert status_packet(1, 0, h("A6 00 00 00")) == h(EMANUAL_PACKETS[3][0])
    assert instruction_packet(1, 0x01) == h(EMANUAL_PACKETS[0][0])
    assert instruction_packet(1, 0x02, h("84 00 04 00")) == h(EMANUAL_PACKETS[2][0])
    assert instruction_packet(0xFE, 0x82, h("84 00 04 00 01 02")) == h(EMANUAL_PACKETS[6][0])


def test_crc_matches_the_sdk_table_on_random_buffers():
    rng = np.random.default_rng(42)
    for _ in range(300):
        buf = rng.integers(0, 256, size=int(rng.integers(1, 80))).tolist()
        assert crc16(bytes(buf)) == SDK.updateCRC(0, buf, len(buf))


def _sdk_stuffed(dxl_id: int, inst: int, params: bytes) -> bytes:
    """What dynamixel-sdk sends for these params (its own addStuffing and CRC)."""
    length = len(params) + 3
    pkt = [0xFF, 0xFF, 0xFD, 0x00, dxl_id, length & 0xFF, length >> 8, inst, *params, 0, 0]
    pkt = SDK.addStuffing(pkt)
    total = (pkt[5] | pkt[6] << 8) + 7
    crc = SDK.updateCRC(0, pkt, total - 2)
    pkt[total - 2], pkt[total - 1] = crc & 0xFF, crc >> 8
    return bytes(pkt[:total])


@pytest.mark.parametrize("params", [
    h("FF FF FD"),
    h("84 00 FF FF FD FF"),
    h("FF FF FD FD FF FF FD 00"),
    h("00 FF FF FD FF FF FD"),
])
def test_stuffing_matches_the_sdk_and_round_trips(params):
    ours = instruction_packet(1, 0x03, params)
    assert ours == _sdk_stuffed(1, 0x03, params)
    assert remove_stuffing(stuff(bytes([0x03]) + params)) == bytes([0x03]) + params
    (parsed,) = list(InstructionParser().feed(ours))
    assert parsed == Instruction(1, 0x03, params, True)


def test_status_packets_are_the_sdks_framing_whatever_their_header_cache_holds():
    """status_packet takes its header's CRC from a cache by (ID, LEN) and continues it over
    the error byte and parameters: every status is still what dynamixel-sdk's addStuffing and
    updateCRC make of it, the same header again (a poll), other IDs and lengths, and
    parameters that need stuffing, including a pattern that starts at the error byte."""
    rng = np.random.default_rng(25)
    for trial in range(400):
        dxl_id = int(rng.choice([1, 2, 3, int(rng.integers(0, 253))]))
        n = int(rng.choice([16, 4, int(rng.integers(0, 60))]))
        params = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        if trial % 4 == 0:  # bytes that stuff: FF FF FD runs
            params = bytes(rng.choice([0xFF, 0xFD, 0x00], n))
        error = int(rng.choice([0, 0x80, 0xFF, int(rng.integers(0, 256))]))
        if trial % 50 == 1:
            error, params = 0xFF, h("FF FD") + params  # the pattern begins at the error byte
        want = _sdk_stuffed(dxl_id, 0x55, bytes([error]) + params)
        assert status_packet(dxl_id, error, params) == want, (dxl_id, error, params)
        assert status_packet(dxl_id, error, params) == want  # the header from the cache


def test_parser_finds_packets_among_noise_and_split_feeds():
    a = instruction_packet(1, 0x02, h("84 00 04 00"))
    b = instruction_packet(2, 0x03, h("40 00 01"))
    stream = h("00 FF 12 FF FF") + a + h("FD") + b
    parser = InstructionParser()
    got = []
    for k in range(0, len(stream), 3):
        got += list(parser.feed(stream[k:k + 3]))
    assert [(i.dxl_id, i.code, i.params) for i in got] == [
        (1, 0x02, h("84 00 04 00")), (2, 0x03, h("40 00 01"))]
    assert all(i.crc_ok for i in got)


def test_parser_marks_a_corrupted_crc():
    bad = bytearray(instruction_packet(1, 0x01))
    bad[-1] ^= 0xFF
    (parsed,) = list(InstructionParser().feed(bytes(bad)))
    assert not parsed.crc_ok and parsed.dxl_id == 1


def test_a_running_crc_continues_over_any_split():
    # crc16 takes two bytes per step; a running CRC (Fast Sync Read's inner CRCs) continues
    # from a split at an odd or even length as the SDK's byte-by-byte table does
    rng = np.random.default_rng(7)
    for _ in range(200):
        buf = rng.integers(0, 256, size=int(rng.integers(2, 60))).tolist()
        k = int(rng.integers(0, len(buf)))
        assert crc16(bytes(buf[k:]), crc16(bytes(buf[:k]))) == SDK.updateCRC(0, buf, len(buf))


def test_the_same_packet_again_parses_the_same_whatever_came_before():
    a = instruction_packet(0xFE, 0x82, h("78 00 10 00 01 02 03"))
    b = instruction_packet(2, 0x03, h("40 00 01"))
    parser = InstructionParser()
    want = Instruction(0xFE, 0x82, h("78 00 10 00 01 02 03"), True)
    assert list(parser.feed(a)) == [want]
    assert list(parser.feed(a)) == [want]  # the poll's packet again
    # a packet split over two feeds, the poll's packet behind it in the second
    assert list(parser.feed(b[:5])) == []
    got = list(parser.feed(b[5:] + a))
    assert got == [Instruction(2, 0x03, h("40 00 01"), True), want]
    bad = bytearray(a)
    bad[-1] ^= 0xFF
    assert [i.crc_ok for i in parser.feed(bytes(bad))] == [False]
    assert list(parser.feed(a)) == [want]
