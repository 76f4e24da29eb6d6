"""Several emulated servos on one half-duplex Protocol 2.0 bus, bytes in, bytes out.

:meth:`ServoBus.receive` takes the bytes a host sends and returns the replies the servos will
send, in the order they send them (hardware reference §4.4, §4.7): one status per servo in the
order of a SYNC_READ's or BULK_READ's parameters, servos in ID order for a broadcast PING, one
combined packet for FAST_SYNC_READ and FAST_BULK_READ. Each reply is produced lazily, at the
moment its servo starts to send it (after its Return Delay Time and the replies before it), so
a reply samples the servo's state at a realistic instant; the transports decide when that is.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from gyrocal.drivers.clock import Clock
from gyrocal.drivers.emulated.dxl.protocol import (
    BROADCAST_ID,
    ERR_CRC,
    ERR_DATA_LENGTH,
    ERR_INSTRUCTION,
    Instruction,
    InstructionParser,
    crc16,
    fast_status_packet,
    status_packet,
)
from gyrocal.drivers.emulated.dxl.servo import EmulatedServo

__all__ = ["PendingReply", "ServoBus"]

PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR = (
    0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10)
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ = 0x82, 0x83, 0x8A
BULK_READ, BULK_WRITE, FAST_BULK_READ = 0x92, 0x93, 0x9A


@dataclass
class PendingReply:
    """A reply a servo will send.

    Attributes
    ----------
    delay_s : float
        Time from the end of the previous transmission on the bus to this reply's first byte
        (the servo's Return Delay Time, hardware reference §5 address 9).
    produce : callable
        Called at the reply's start time; returns the bytes to send (empty: nothing is sent,
        for example a dropped status).
    servo_id : int or None
        The servo that sends it (None for a combined fast-read packet).
    """

    delay_s: float
    produce: Callable[[], bytes]
    servo_id: int | None = None


class ServoBus:
    """Emulated servos sharing one bus.

    Parameters
    ----------
    servos : iterable of EmulatedServo
        The servos; their IDs must differ.
    clock : Clock
        The shared clock (the servos' clock).
    """

    def __init__(self, servos: Iterable[EmulatedServo], clock: Clock) -> None:
        self.servos: list[EmulatedServo] = list(servos)
        ids = [s.dxl_id for s in self.servos]
        if len(set(ids)) != len(ids):
            raise ValueError(f"servo IDs on one bus must differ, got {ids}")
        self.clock = clock
        self.lock = threading.RLock()
        for s in self.servos:
            s.lock = self.lock
        self._parser = InstructionParser()
        #: Instruction names received, counted (for tests and benchmarks).
        self.instruction_counts: dict[str, int] = {}

    def servo(self, dxl_id: int) -> EmulatedServo:
        """The servo that currently has ``dxl_id``.

        Raises
        ------
        KeyError
            If no servo on the bus has that ID.
        """
        for s in self.servos:
            if s.dxl_id == dxl_id:
                return s
        raise KeyError(f"no emulated servo with ID {dxl_id}; IDs on the bus: "
                       f"{[s.dxl_id for s in self.servos]}")

    def receive(self, data: bytes, baudrate: int | None = None) -> list[PendingReply]:
        """Feed bytes sent by the host; return the replies of every packet they complete.

        Parameters
        ----------
        data : bytes
            Bytes as sent on the wire.
        baudrate : int or None
            The host's baud rate; servos set to another rate do not hear the packet (None: all
            hear it, as on a pseudo-terminal).
        """
        with self.lock:
            replies: list[PendingReply] = []
            for instr in self._parser.feed(bytes(data)):
                replies += self.handle(instr, baudrate)
            return replies

    # ---- dispatch ------------------------------------------------------------------------
    def handle(self, instr: Instruction, baudrate: int | None = None) -> list[PendingReply]:
        """Execute one instruction packet; return the replies it causes."""
        with self.lock:
            now = self.clock.monotonic()
            name = instr.name if instr.crc_ok else "CRC_ERROR"
            self.instruction_counts[name] = self.instruction_counts.get(name, 0) + 1
            listeners = [s for s in self.servos if s.hears(now, baudrate)]
            if instr.dxl_id != BROADCAST_ID:
                target = next((s for s in listeners if s.dxl_id == instr.dxl_id), None)
                if instr.crc_ok:
                    self._shadow(listeners, instr, now)
                if target is None:
                    return []
                target.note_instruction(now)
                if not instr.crc_ok:
                    return [self._reply(target, "other", lambda: (ERR_CRC, b""))]
                return self._unicast(target, instr)
            if not instr.crc_ok:
                return []
            return self._broadcast(listeners, instr, now)

    def _shadow(self, listeners: list[EmulatedServo], instr: Instruction, now: float) -> None:
        """A packet to an ID that is some servos' Secondary (Shadow) ID (control table address
        12): every such servo whose own ID differs executes it and none replies (e-Manual, X
        series control table, Secondary(Shadow) ID: "Dynamixels with the same Secondary ID
        value form a group"; "ID(7) has a higher priority"; "The EEPROM area of the Control
        Table cannot be modified with Secondary ID(12). Only the RAM area can be modified"; "If
        Instruction Packet ID is the same as Secondary ID(12), the Status Packet will not be
        returned"; 253–255 deactivate it).

        The e-Manual names no instruction; its rule is the area each one changes. WRITE and
        REG_WRITE act on the RAM area only, and ACTION; REBOOT (torque off, the RAM back to its
        power-up values, the position re-based) and CLEAR (the multi-turn count of Present
        Position) change nothing in the EEPROM, so they act too, their status unsent (a CLEAR
        while moving fails with nobody told); FACTORY_RESET rewrites the EEPROM and does not
        act; a PING or READ is only a status, so nothing happens ⚠ (the reading of REBOOT,
        CLEAR and FACTORY_RESET follows from the rule, not from a sentence about them)."""
        group = [s for s in listeners
                 if s.dxl_id != instr.dxl_id and s.secondary_id == instr.dxl_id]
        if not group:
            return
        code, p = instr.code, instr.params
        for s in group:
            s.note_instruction(now)
            if code == ACTION:
                s.action()
            elif code == REBOOT:
                s.reboot()
            elif code == CLEAR:
                s.clear_multi_turn(p)
            elif code in (WRITE, REG_WRITE) and len(p) >= 3:
                addr = p[0] | p[1] << 8
                if not s.in_ram(addr, len(p) - 2):
                    continue
                s.write(addr, p[2:]) if code == WRITE else s.reg_write(addr, p[2:])

    def _reply(self, servo: EmulatedServo, kind: str,
               make: Callable[[], tuple[int, bytes]],
               then: Callable[[], None] | None = None) -> PendingReply:
        """A normal (stuffed) status packet from ``servo``, produced when it is sent; ``then``
        runs once it has been (an instruction that changes the servo's ID or baud rate acts
        after its status packet, as the e-Manual's Factory Reset example shows)."""

        lock, clock = self.lock, self.clock

        def produce() -> bytes:
            with lock:
                try:
                    now = clock.monotonic()
                    if not servo.answers(now) or not servo.status_level_allows(kind):
                        return b""
                    error, params = make()
                    fault = servo.reply_fault()
                    if fault == "drop":
                        return b""
                    packet = status_packet(servo.dxl_id, servo.error_byte(error), params)
                    if fault == "corrupt":
                        packet = packet[:-1] + bytes([packet[-1] ^ 0x5A])
                    return packet
                finally:
                    if then is not None:
                        then()

        return PendingReply(servo.return_delay_s, produce, servo.dxl_id)

    def _unicast(self, s: EmulatedServo, instr: Instruction) -> list[PendingReply]:
        code, p = instr.code, instr.params
        if code == PING:
            return [self._reply(s, "ping", lambda: (0, s.ping()))]
        if code == READ:
            if len(p) != 4:
                return [self._reply(s, "read", lambda: (ERR_DATA_LENGTH, b""))]
            addr, length = p[0] | p[1] << 8, p[2] | p[3] << 8
            return [self._reply(s, "read", lambda: s.read(addr, length))]
        if code in (WRITE, REG_WRITE):
            if len(p) < 3:
                err = ERR_DATA_LENGTH
            else:
                addr = p[0] | p[1] << 8
                err = s.write(addr, p[2:]) if code == WRITE else s.reg_write(addr, p[2:])
            return [self._reply(s, "other", lambda: (err, b""))]
        if code == ACTION:
            err = s.action()
            return [self._reply(s, "other", lambda: (err, b""))]
        if code == REBOOT:
            s.reboot()  # clears the hardware error: the status carries no alert
            return [self._reply(s, "other", lambda: (0, b""))]
        if code == FACTORY_RESET:
            if len(p) != 1:
                return [self._reply(s, "other", lambda: (ERR_DATA_LENGTH, b""))]
            err = s.factory_reset(p[0], dry_run=True)
            return [self._reply(s, "other", lambda: (err, b""),
                                then=None if err else lambda: s.factory_reset(p[0]))]
        if code == CLEAR:
            err = s.clear_multi_turn(p)
            return [self._reply(s, "other", lambda: (err, b""))]
        return [self._reply(s, "other", lambda: (ERR_INSTRUCTION, b""))]

    def _broadcast(self, listeners: list[EmulatedServo], instr: Instruction,
                   now: float) -> list[PendingReply]:
        code, p = instr.code, instr.params
        by_id = {s.dxl_id: s for s in listeners}
        if code == PING:
            for s in listeners:
                s.note_instruction(now)
            return [self._reply(s, "ping", lambda s=s: (0, s.ping()))
                    for s in sorted(listeners, key=lambda s: s.dxl_id)]
        if code in (WRITE, REG_WRITE) and len(p) >= 3:
            addr = p[0] | p[1] << 8
            for s in listeners:
                s.note_instruction(now)
                s.write(addr, p[2:]) if code == WRITE else s.reg_write(addr, p[2:])
            return []
        if code == ACTION:
            for s in listeners:
                s.note_instruction(now)
                s.action()
            return []
        if code == REBOOT:
            for s in listeners:
                s.reboot()
            return []
        if code == FACTORY_RESET and len(p) == 1 and p[0] != 0xFF:
            # a broadcast Factory Reset acts with options 0x01 and 0x02 only, never with 0xFF
            # (e-Manual, Protocol 2.0, Factory Reset: firmware v42 and above); no status
            for s in listeners:
                s.note_instruction(now)
                s.factory_reset(p[0])
            return []
        if code in (SYNC_READ, FAST_SYNC_READ) and len(p) >= 5:
            addr, length = p[0] | p[1] << 8, p[2] | p[3] << 8
            ids = list(p[4:])
            for i in ids:
                if i in by_id:
                    by_id[i].note_instruction(now)
            if code == SYNC_READ:
                return [self._reply(by_id[i], "read", lambda s=by_id[i]: s.read(addr, length))
                        for i in ids if i in by_id]
            return self._fast_read(by_id, [(i, addr, length) for i in ids])
        if code == SYNC_WRITE and len(p) >= 4:
            addr, length = p[0] | p[1] << 8, p[2] | p[3] << 8
            body = p[4:]
            step = length + 1
            for k in range(0, len(body) - step + 1, step):
                s = by_id.get(body[k])
                if s is not None:
                    s.note_instruction(now)
                    s.write(addr, body[k + 1: k + step])
            return []
        if code in (BULK_READ, FAST_BULK_READ):
            entries = []
            for k in range(0, len(p) - 4, 5):
                entries.append((p[k], p[k + 1] | p[k + 2] << 8, p[k + 3] | p[k + 4] << 8))
            for i, _, _ in entries:
                if i in by_id:
                    by_id[i].note_instruction(now)
            if code == BULK_READ:
                return [self._reply(by_id[i], "read", lambda s=by_id[i], a=a, n=n: s.read(a, n))
                        for i, a, n in entries if i in by_id]
            return self._fast_read(by_id, entries)
        if code == BULK_WRITE:
            k = 0
            while k + 5 <= len(p):
                i, addr, length = p[k], p[k + 1] | p[k + 2] << 8, p[k + 3] | p[k + 4] << 8
                s = by_id.get(i)
                if s is not None:
                    s.note_instruction(now)
                    s.write(addr, p[k + 5: k + 5 + length])
                k += 5 + length
            return []
        return []

    def _fast_read(self, by_id: dict[int, EmulatedServo],
                   entries: list[tuple[int, int, int]]) -> list[PendingReply]:
        """FAST_SYNC_READ / FAST_BULK_READ: one packet, no stuffing, running CRCs (§4.6).

        The servos append their blocks in parameter order; a servo that is absent, silent or
        drops its reply cuts the packet short there, so the host sees a timeout or a corrupt
        packet, as on a real bus.
        """
        if not entries or entries[0][0] not in by_id:
            return []
        first = by_id[entries[0][0]]

        def produce() -> bytes:
            with self.lock:
                now = self.clock.monotonic()
                blocks = []
                corrupt = False
                complete = True
                for i, addr, length in entries:
                    s = by_id.get(i)
                    if s is None or not s.answers(now) or not s.status_level_allows("read"):
                        complete = False
                        break
                    err, data = s.read(addr, length)
                    fault = s.reply_fault()
                    if fault == "drop":
                        complete = False
                        break
                    corrupt |= fault == "corrupt"
                    if len(data) != length:  # Access Error: pad so the framing stays intact
                        data = bytes(length)
                    blocks.append((s.error_byte(err), i, data))
                if not blocks:
                    return b""
                packet = fast_status_packet(blocks)
                if not complete:
                    # the header announced every block; the missing ones never arrive
                    full = sum(n + 4 for _, _, n in entries) + 1
                    head = bytearray(packet[:8])
                    head[5], head[6] = full & 0xFF, full >> 8
                    packet = bytes(head) + packet[8:]
                    # recompute inner CRCs over the corrected header so the early blocks stay
                    # valid, as the servos would have sent them
                    out = bytearray(packet[:8])
                    pos = 8
                    for (_, _, data) in blocks:
                        out += packet[pos: pos + 2 + len(data)]
                        c = crc16(out)
                        out += bytes([c & 0xFF, c >> 8])
                        pos += 4 + len(data)
                    packet = bytes(out)
                if corrupt:
                    packet = packet[:-1] + bytes([packet[-1] ^ 0x5A])
                return packet

        return [PendingReply(first.return_delay_s, produce, None)]
