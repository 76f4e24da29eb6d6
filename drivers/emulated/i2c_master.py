"""The auxiliary I²C master shared by the emulated MPU-9250 and ICM-20948: slaves 0–3 read into
the EXT_SENS_DATA registers (or write their DO byte) once per master cycle, slave 4 makes one
transfer and reports SLV4_DONE.

Both chips lay the same registers out differently (MPU-9250 register map RM-MPU-9250A-00
registers 36–54 and 99–102: all in one bank; ICM-20948 DS-000189 user bank 3 for the slave
registers, bank 0 for I2C_MST_STATUS and EXT_SLV_SENS_DATA); :class:`MasterLayout` says where
each is, from the chips' register tables. The bits are the same on both:

- SLVn_ADDR bit 7 = read (1) or write (0), bits 6:0 the slave's address.
- SLVn_CTRL bit 7 EN, bit 6 BYTE_SW (swap the bytes of each pair read), bit 5 REG_DIS (no
  register address is sent), bits 3:0 LENG. A read slave puts LENG bytes into the next free
  EXT_SENS_DATA bytes, in slave order; a write slave writes its DO byte.
- SLV4_CTRL bit 7 EN clears itself when slave 4's single transfer is done; the read byte goes to
  SLV4_DI.
- I2C_MST_STATUS bit 6 I2C_SLV4_DONE, bits 0–4 I2C_SLVn_NACK (a slave that does not acknowledge).

The master runs one cycle per sample of the chip (the ICM-20948's I2C_MST_ODR_CONFIG: "when the
gyroscope is enabled, all sensors (including I2C_MASTER) use the gyroscope ODR"; the MPU-9250's
at its sample rate); I2C_SLV4_DLY and the per-slave delay are not modelled (every slave runs
every cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

from gyrocal.drivers.emulated.smbus import I2CDevice

__all__ = ["AuxI2CMaster", "MasterLayout"]

_READ = 0x80  # SLVn_ADDR
_EN, _BYTE_SW, _REG_DIS, _LENG = 0x80, 0x40, 0x20, 0x0F  # SLVn_CTRL
_SLV4_DONE = 0x40  # I2C_MST_STATUS
_EXT_BYTES = 24


@dataclass(frozen=True)
class MasterLayout:
    """Where a chip keeps its I²C-master registers (addresses in the register block the slave
    configuration lives in; EXT_SENS_DATA in the block the data registers live in).

    Parameters
    ----------
    slv0_addr, slv_stride : int
        SLVn_ADDR at ``slv0_addr + slv_stride·n``; SLVn_REG and SLVn_CTRL follow it.
    slv0_do, do_stride : int
        SLVn_DO at ``slv0_do + do_stride·n``.
    slv4_addr, slv4_reg, slv4_ctrl, slv4_do, slv4_di : int
        Slave 4's registers.
    ext_sens_data_00 : int
        EXT_SENS_DATA_00 (24 bytes).
    """

    slv0_addr: int
    slv_stride: int
    slv0_do: int
    do_stride: int
    slv4_addr: int
    slv4_reg: int
    slv4_ctrl: int
    slv4_do: int
    slv4_di: int
    ext_sens_data_00: int


class AuxI2CMaster:
    """The master of a chip's auxiliary bus.

    Parameters
    ----------
    layout : MasterLayout
        Where the chip keeps the registers.
    aux : dict of int -> I2CDevice
        The devices on the auxiliary bus by 7-bit address.
    """

    def __init__(self, layout: MasterLayout, aux: dict[int, I2CDevice]) -> None:
        self.layout = layout
        self.aux = aux

    def cycle(self, config: bytearray, data: bytearray) -> int:
        """One master cycle: slaves 0–3 in order, then slave 4.

        Parameters
        ----------
        config : bytearray
            The register block holding the SLVn registers (SLV4_DI is written there).
        data : bytearray
            The register block holding EXT_SENS_DATA.

        Returns
        -------
        int
            The I2C_MST_STATUS bits the cycle sets (NACKs, SLV4_DONE).
        """
        lay, status = self.layout, 0
        ext = lay.ext_sens_data_00
        for n in range(4):
            base = lay.slv0_addr + lay.slv_stride * n
            ctrl = config[base + 2]
            if not ctrl & _EN:
                continue
            length = ctrl & _LENG
            got = self._transfer(config[base], config[base + 1],
                                 config[lay.slv0_do + lay.do_stride * n], length,
                                 no_register=bool(ctrl & _REG_DIS))
            if got is None:
                status |= 1 << n  # I2C_SLVn_NACK
                continue
            if not length or not config[base] & _READ:
                continue
            if ctrl & _BYTE_SW:
                got = b"".join(got[i:i + 2][::-1] for i in range(0, len(got), 2))
            room = max(0, lay.ext_sens_data_00 + _EXT_BYTES - ext)
            data[ext:ext + min(room, len(got))] = got[:room]
            ext += len(got)
        ctrl4 = config[lay.slv4_ctrl]
        if ctrl4 & _EN:
            got = self._transfer(config[lay.slv4_addr], config[lay.slv4_reg],
                                 config[lay.slv4_do], 1, no_register=bool(ctrl4 & _REG_DIS))
            if got is None:
                status |= 1 << 4  # I2C_SLV4_NACK
            elif got:
                config[lay.slv4_di] = got[0]
            config[lay.slv4_ctrl] = ctrl4 & ~_EN
            status |= _SLV4_DONE
        return status

    def _transfer(self, addr: int, register: int, out: int, length: int, *,
                  no_register: bool) -> bytes | None:
        """One slave's transfer: the bytes read (``b""`` for a write), or ``None`` on a NACK."""
        dev = self.aux.get(addr & 0x7F)
        if dev is None or dev.i2c_ack() is not None:
            return None
        if addr & _READ:
            if not no_register:
                dev.i2c_write(bytes([register]))
            return bytes(dev.i2c_read(length)) if length else b""
        dev.i2c_write(bytes([out]) if no_register else bytes([register, out]))
        return b""
