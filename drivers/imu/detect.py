"""Find the supported IMUs on an I²C bus, the kernel's way: read each family's identity register
at the addresses the family can have, and name what answers.

Only reads are used (no reset, no bank switch), so a scan leaves every chip as it was. A chip
that answers with a sibling's identity (an MPU-6050, an ICM-42605, an LSM6DS3...) is named with
what gyrocal says about it; one that answers nothing known is reported by address only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["FoundChip", "scan_bus"]


@dataclass(frozen=True)
class FoundChip:
    """A device that answered on the bus.

    Parameters
    ----------
    address : int
        Its 7-bit address.
    model : str or None
        The gyrocal model name (``"icm42688p"``) if a reader drives it, else ``None``.
    title : str
        What it is (``"ICM-42688-P"``), or a sibling's description, or ``"an unknown device"``.
    who_am_i : int or None
        The identity byte that named it (``None`` for an unknown device).
    register : int or None
        Where that byte was read.
    """

    address: int
    model: str | None
    title: str
    who_am_i: int | None = None
    register: int | None = None


def _families() -> list[Any]:
    from gyrocal.drivers.imu import READERS

    return list({cls.family.name: cls.family for cls in READERS.values()}.values())


def scan_bus(bus: Any, addresses: tuple[int, ...] | None = None) -> list[FoundChip]:
    """Identify the devices at the supported chips' addresses.

    Parameters
    ----------
    bus : smbus2.SMBus-like
        An open bus (``read_byte_data``).
    addresses : tuple of int, optional
        Where to look; every address a supported family can have by default.

    Returns
    -------
    list of FoundChip
        One per address that acknowledged, in address order.
    """
    families = _families()
    if addresses is None:
        addresses = tuple(sorted({a for f in families for a in f.addresses}))
    found = []
    for address in addresses:
        answered = False
        hit: FoundChip | None = None
        for fam in families:
            if address not in fam.addresses:
                continue
            try:
                who = int(bus.read_byte_data(address, fam.who_am_i_register))
            except OSError:
                continue  # nothing there, or it refused this register
            answered = True
            model = fam.model_for(who)
            if model is not None:
                hit = FoundChip(address, model.name, model.title, who, fam.who_am_i_register)
                break
            if who in fam.siblings and hit is None:
                hit = FoundChip(address, None, fam.siblings[who], who, fam.who_am_i_register)
        if hit is not None:
            found.append(hit)
        elif answered:
            found.append(FoundChip(address, None, "an unknown device"))
    return found
