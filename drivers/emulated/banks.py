"""What the emulated ICM-20948 and ICM-42688-P share: registers spread over user banks selected
by a register readable in every bank, and a FIFO read through a data port in bank 0.

On both chips (DS-000189 REG_BANK_SEL 0x7F, USER_BANK[5:4]; DS-000347 REG_BANK_SEL 0x76,
BANK_SEL[2:0]) a write to the bank register selects the bank every other access reaches until
the next such write; bank 0 holds identity, power, data and FIFO, and the other banks are plain
memory here (the chips' own models add what their banks mean). A burst that reaches the FIFO's
data port keeps reading it, popping one byte each; an empty FIFO returns a fill byte.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

__all__ = ["UserBanks"]


class UserBanks:
    """Mixin for an emulated chip (before :class:`~gyrocal.drivers.emulated.imu_chips.
    _EmulatedImu` in the bases): user banks and the bank-0 FIFO data port.

    Subclasses set the class attributes and keep their FIFO bytes in ``self._fifo`` (a
    ``bytearray``); :meth:`_fifo_fill` gives the byte an empty FIFO returns.
    """

    #: The bank select register (in every bank), the shift and mask of its bank field.
    bank_register: ClassVar[int]
    bank_shift: ClassVar[int] = 0
    bank_mask: ClassVar[int]
    #: The banks besides 0 that hold memory.
    other_banks: ClassVar[tuple[int, ...]]
    #: Reset values of those banks' registers that do not reset to 0: bank → register → value.
    bank_reset_values: ClassVar[Mapping[int, Mapping[int, int]]] = {}
    #: The FIFO data port in bank 0.
    fifo_port: ClassVar[int]

    _bank: int
    _banks: dict[int, bytearray]
    _fifo: bytearray
    _ptr: int

    def _reset_banks(self) -> None:
        """Select bank 0 and give the other banks their reset values
        (:attr:`bank_reset_values`, 0 elsewhere)."""
        self._bank = 0
        self._banks = {b: bytearray(128) for b in self.other_banks}
        for bank, values in self.bank_reset_values.items():
            for register, value in values.items():
                self._banks[bank][register] = value

    @property
    def bank(self) -> int:
        """The user bank the bank register selects."""
        return self._bank

    def _select_bank(self, register: int, value: int) -> bool:
        """Take a write to the bank register (True), or say it is not one (False)."""
        if register != self.bank_register:
            return False
        self._bank = (value & self.bank_mask) >> self.bank_shift
        return True

    def _banked_read(self, register: int) -> int | None:
        """The bank register's value, or a register of a bank other than 0; None in bank 0."""
        if register == self.bank_register:
            return self._bank << self.bank_shift
        if self._bank:
            return self._banks.get(self._bank, bytearray(128))[register]
        return None

    def _next_pointer(self, register: int) -> int:
        if register == self.fifo_port and not self._bank:
            return register  # a data port: the burst keeps popping the FIFO
        return super()._next_pointer(register)  # type: ignore[misc]

    def _fifo_fill(self) -> int:
        """The byte an empty FIFO returns."""
        return 0xFF

    def _read_fast(self, length: int) -> bytes | None:
        if self._ptr != self.fifo_port or self._bank:
            return None
        take = min(length, len(self._fifo))
        out = bytes(self._fifo[:take])
        del self._fifo[:take]
        self._popped(out)
        return out + bytes([self._fifo_fill()]) * (length - take)

    def _popped(self, data: bytes) -> None:
        """Called with the bytes each FIFO read popped."""

    def _read_port_byte(self) -> int:
        return self._read_fast(1)[0]  # type: ignore[index]
