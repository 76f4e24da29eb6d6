"""Dynamixel Protocol 2.0 framing: CRC-16, byte stuffing, packets (hardware reference §4).

Device-side code: it builds status packets and parses instruction packets from a byte stream.
The host side is dynamixel-sdk itself; nothing here is shared with the driver.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import reduce
from operator import getitem, xor

__all__ = [
    "BROADCAST_ID",
    "HEADER",
    "INSTRUCTIONS",
    "Instruction",
    "InstructionParser",
    "crc16",
    "fast_status_packet",
    "remove_stuffing",
    "status_packet",
    "stuff",
]

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
STATUS = 0x55

#: Instruction codes (hardware reference §4.4).
INSTRUCTIONS: dict[int, str] = {
    0x01: "PING",
    0x02: "READ",
    0x03: "WRITE",
    0x04: "REG_WRITE",
    0x05: "ACTION",
    0x06: "FACTORY_RESET",
    0x08: "REBOOT",
    0x10: "CLEAR",
    0x82: "SYNC_READ",
    0x83: "SYNC_WRITE",
    0x8A: "FAST_SYNC_READ",
    0x92: "BULK_READ",
    0x93: "BULK_WRITE",
    0x9A: "FAST_BULK_READ",
}

# Status error numbers (hardware reference §4.5).
ERR_RESULT_FAIL = 1
ERR_INSTRUCTION = 2
ERR_CRC = 3
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7
ERRBIT_ALERT = 0x80


def _make_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def _make_positions(span: int) -> tuple[tuple[int, ...], ...]:
    """Per-position tables for runs of up to ``span`` bytes: ``[span - n + i][b]`` is what byte
    ``b`` at position ``i`` of ``n`` bytes adds to their CRC (from 0): the CRC of ``b`` followed
    by ``n - 1 - i`` zero bytes. The CRC is linear (XOR), so a run's CRC is the XOR of its bytes'
    entries."""
    rows = [_TABLE]
    for _ in range(span - 1):  # one more zero byte through the register
        rows.append(tuple(((c << 8) & 0xFFFF) ^ _TABLE[c >> 8] for c in rows[-1]))
    return tuple(reversed(rows))


#: Longest run :func:`crc16` does with :data:`_POSITIONS` (a status packet of a sync read of up
#: to 53 bytes); longer runs go byte by byte.
_SPAN = 64
_POSITIONS = _make_positions(_SPAN)


def crc16(data: bytes | bytearray, crc: int = 0) -> int:
    """CRC-16 of Protocol 2.0: polynomial 0x8005, init 0, MSB first, no final XOR (§4.2).

    Parameters
    ----------
    data : bytes
        The bytes from the first 0xFF of the header up to the byte before CRC_L, stuffing
        included.
    crc : int
        A running CRC to continue (used by Fast Sync Read, §4.6).

    Notes
    -----
    Runs of 2 to :data:`_SPAN` bytes XOR their bytes' entries of :data:`_POSITIONS` (a
    running CRC ``c`` is the same as ``c``'s two bytes XORed into the first two); others go byte
    by byte through the table.
    """
    n = len(data)
    if 2 <= n <= _SPAN:
        tables = _POSITIONS[_SPAN - n:]
        out = reduce(xor, map(getitem, tables, data), 0)
        if crc:
            out ^= tables[0][crc >> 8] ^ tables[1][crc & 0xFF]
        return out
    table = _TABLE
    for b in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert a 0xFD after every ``FF FF FD`` in ``body`` (instruction/status onwards, §4.3).

    ``body`` starts at the INST byte; the two bytes before it (LEN_L, LEN_H) never complete a
    header pattern with it, because the SDK and the e-manual scan from the instruction byte on.
    """
    if b"\xff\xff\xfd" not in body:  # nothing to stuff (the usual case)
        return bytes(body)
    out = bytearray()
    for b in body:
        out.append(b)
        if b == 0xFD and len(out) >= 3 and out[-2] == 0xFF and out[-3] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def remove_stuffing(body: bytes) -> bytes:
    """Undo :func:`stuff`: drop the extra 0xFD of every ``FF FF FD FD``."""
    if b"\xff\xff\xfd\xfd" not in body:  # nothing was stuffed (the usual case)
        return bytes(body)
    out = bytearray()
    i = 0
    n = len(body)
    while i < n:
        b = body[i]
        out.append(b)
        if b == 0xFD and len(out) >= 3 and out[-2] == 0xFF and out[-3] == 0xFF \
                and i + 1 < n and body[i + 1] == 0xFD:
            i += 1  # skip the stuffing byte
        i += 1
    return bytes(out)


def _frame(dxl_id: int, body: bytes) -> bytes:
    """Header + ID + LEN + stuffed body + CRC."""
    stuffed = stuff(body) if b"\xff\xff\xfd" in body else body
    length = len(stuffed) + 2
    packet = HEADER + bytes((dxl_id & 0xFF, length & 0xFF, (length >> 8) & 0xFF)) + stuffed
    crc = crc16(packet)
    return packet + bytes((crc & 0xFF, crc >> 8))


#: Status packets' first eight bytes (``FF FF FD 00 ID LEN_L LEN_H 55``) and their CRC, by
#: ``(ID, LEN)``: a servo answers a poll with the same header again and again.
_STATUS_HEADS: dict[tuple[int, int], tuple[bytes, int]] = {}


def status_packet(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A (stuffed) status packet: ``FF FF FD 00 ID LEN 55 ERR PARAM… CRC`` (§4.1, §4.3).

    Without stuffing to do (the usual case) the header's CRC is taken up from
    :data:`_STATUS_HEADS` and continued over the error byte and parameters: the CRC of a run
    continued from a running CRC is the CRC of the whole (:func:`crc16`).
    """
    rest = bytes((error & 0xFF,)) + params
    if b"\xff\xff\xfd" in rest:  # STATUS (0x55) cannot begin the pattern: rest can
        return _frame(dxl_id, bytes((STATUS,)) + rest)
    key = (dxl_id & 0xFF, len(rest) + 3)
    head = _STATUS_HEADS.get(key)
    if head is None:
        if len(_STATUS_HEADS) > 1024:
            _STATUS_HEADS.clear()
        length = key[1]
        packet = HEADER + bytes((key[0], length & 0xFF, (length >> 8) & 0xFF, STATUS))
        head = _STATUS_HEADS[key] = (packet, crc16(packet))
    crc = crc16(rest, head[1])
    return head[0] + rest + bytes((crc & 0xFF, crc >> 8))


def instruction_packet(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A (stuffed) instruction packet, for tests and tools that talk to the emulator directly."""
    return _frame(dxl_id, bytes([instruction]) + bytes(params))


def fast_status_packet(blocks: list[tuple[int, int, bytes]]) -> bytes:
    """The single Fast Sync/Bulk Read status packet (§4.6): no stuffing, running inner CRCs.

    Parameters
    ----------
    blocks : list of (error, id, data)
        One block per servo, in the order of the instruction's parameters.
    """
    # LEN = INST + Σ(ERR + ID + DATA + CRC): the last block's CRC is the packet's CRC.
    length = 1 + sum(len(d) + 4 for _, _, d in blocks)
    packet = bytearray(HEADER + bytes([BROADCAST_ID, length & 0xFF, (length >> 8) & 0xFF, STATUS]))
    for error, dxl_id, data in blocks:
        packet += bytes([error & 0xFF, dxl_id & 0xFF]) + bytes(data)
        crc = crc16(packet)
        packet += bytes([crc & 0xFF, crc >> 8])
    return bytes(packet)


@dataclass(frozen=True)
class Instruction:
    """A parsed instruction packet.

    Attributes
    ----------
    dxl_id : int
        The target ID (0xFE for broadcast).
    code : int
        The instruction byte.
    params : bytes
        The parameters, stuffing removed.
    crc_ok : bool
        False if the CRC did not match (the device answers with a CRC error, §4.5).
    """

    dxl_id: int
    code: int
    params: bytes
    crc_ok: bool = True

    @property
    def name(self) -> str:
        """The instruction's name (``"READ"``), or its code in hex if unknown."""
        name = INSTRUCTIONS.get(self.code)
        return name if name is not None else f"0x{self.code:02X}"


class InstructionParser:
    """Incremental parser of instruction packets from a byte stream.

    Bytes that do not form a packet are skipped, as a device does while it hunts for the next
    header (``FF FF FD 00``). A packet whose CRC fails is still returned, marked ``crc_ok=False``.
    """

    #: The largest LEN a device accepts (dynamixel-sdk's TXPACKET_MAX_LEN is 1024).
    MAX_LENGTH = 1024

    def __init__(self) -> None:
        self._buf = bytearray()
        #: The last packet that came whole into an empty buffer, and what it parsed to: a
        #: host polling the same way sends the same bytes again and again (a gimbal's
        #: SYNC_READ), and they parse the same.
        self._last: tuple[bytes, Instruction] | None = None

    def feed(self, data: bytes) -> Iterator[Instruction]:
        """Add ``data`` and yield every complete instruction packet it finishes."""
        last = self._last
        if last is not None and not self._buf and data == last[0]:
            yield last[1]
            return
        whole = not self._buf
        self._buf += data
        buf = self._buf
        while True:
            start = buf.find(HEADER[:3])
            if start < 0:
                # keep a possible partial header at the end
                keep = 2 if buf.endswith(b"\xff\xff") else (1 if buf.endswith(b"\xff") else 0)
                del buf[: len(buf) - keep]
                return
            if start:
                del buf[:start]
            if len(buf) < 7:
                return
            if buf[3] != 0x00:  # FF FF FD FD is stuffing, not a header; reserved must be 0
                del buf[:1]
                continue
            length = buf[5] | (buf[6] << 8)
            if length < 3 or length > self.MAX_LENGTH:
                del buf[:1]
                continue
            total = 7 + length
            if len(buf) < total:
                return
            packet = bytes(buf[:total])
            del buf[:total]
            crc = packet[-2] | (packet[-1] << 8)
            body = remove_stuffing(packet[7:-2])
            if not body:
                continue
            instr = Instruction(packet[4], body[0], body[1:], crc16(packet[:-2]) == crc)
            if whole and not buf and len(packet) == len(data):
                self._last = (packet, instr)
            yield instr
