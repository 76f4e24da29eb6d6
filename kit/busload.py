"""How much of an I²C bus the planned sensors' samples take, before a run (issue 15).

Every sample a sensor produces must cross its bus: a bus carries at most its clock rate in bits,
9 a byte (8 data bits and the ACK), so its load is

.. math:: L = \\frac{9}{f_{bus}} \\sum_s \\Big[ P_s\\, r_s \\big(1 + \\tfrac{3}{32}\\big)
          + 5\\, f_{loop} \\Big],

with ``P_s`` the bytes the reader drains per sample of sensor ``s`` (its chip's
``fifo_sample_bytes``: an MPU-9250 FIFO frame is 14), ``r_s`` its output data rate, 3 bytes of
addressing (address + register, repeated-start address) per 32-byte SMBus block
(``BLOCK_MAX``), and one FIFO-count read (2 bytes and 3 of addressing) per loop iteration at
``f_loop`` (``gimbal.sample_hz``). One MPU-9250 at 1 kHz on a 400 kHz bus is 31.5 % in its
payload alone (14 × 9 × 1000 / 400 000) and 36.7 % with the addressing. Above 100 % the FIFOs
must overflow whatever the host does; the emulated bus (:mod:`gyrocal.drivers.emulated.smbus`,
the same 9 bits a byte) has been loss-free up to :data:`WARN_LOAD` (``python -m bench
multi``), so above it a run is warned about.

gyrocal's protocol loop drains every sensor in turn from one thread, and an I²C transfer holds
the thread for its whole time on the wire (an ``ioctl`` on Linux; the emulated buses charge the
one shared clock the same way), so the loads of **all** buses add up too: a second bus gives a
plate more wires, not more time (``python -m bench multi``, Table 1b: four sensors at about
1 kHz lose samples on two buses, 82 % and 87 % each, 169 % together, as on one). The check
therefore applies to each bus and to their sum.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["BUS_HZ", "REFUSE_LOAD", "WARN_LOAD", "BusLoad", "bus_loads", "check_bus_loads"]

#: The I²C clock gyrocal assumes, Hz: fast mode, what the Raspberry Pi's ``i2c_arm_baudrate``
#: is usually set to for sensors and what the emulated bus runs at.
BUS_HZ = 400_000.0
#: A load above this is refused (the FIFOs must overflow).
REFUSE_LOAD = 1.0
#: A load above this is warned about: beyond the highest load the emulated bus has been seen
#: loss-free at (4 sensors at 500/500/416/416 Hz, 89 %, ``python -m bench multi``; the next
#: level, 169 %, lost samples). A figure of the emulator, not of a Raspberry Pi's adapter.
WARN_LOAD = 0.9
_BLOCK = 32  # smbus2's I2C_SMBUS_BLOCK_MAX
_ADDRESSING = 3  # bytes per block transfer: address + register, repeated-start address
_COUNT_READ = 5  # FIFO count: 2 bytes and the addressing


@dataclass(frozen=True)
class BusLoad:
    """One bus's planned load.

    Attributes
    ----------
    bus : int
        The I²C bus number (``/dev/i2c-N``).
    load : float
        Fraction of the bus's bits the sensors' samples need (1.0 = all of them).
    sensors : tuple of str
        The sensors on it, each as ``name (model at ODR Hz: share %)``.
    """

    bus: int
    load: float
    sensors: tuple[str, ...]


def sample_bytes(model: str) -> int:
    """Bytes the reader of ``model`` drains per sample (its chip family's data
    ``fifo_sample_bytes``)."""
    from gyrocal.drivers.imu import READERS

    return int(READERS[model].family.extra["fifo_sample_bytes"])


def sensor_bits_per_s(model: str, odr_hz: float, loop_hz: float) -> float:
    """Bits a second one sensor needs on its bus (module docstring)."""
    payload = sample_bytes(model) * odr_hz * (1.0 + _ADDRESSING / _BLOCK)
    return 9.0 * (payload + _COUNT_READ * loop_hz)


def bus_loads(sensors: Iterable[Mapping[str, Any]], loop_hz: float,
              bus_hz: float = BUS_HZ) -> list[BusLoad]:
    """Each bus's load for sensors given as config entries (``name``, ``model``, ``bus``,
    ``odr_hz``), in bus order."""
    per_bus: dict[int, list[tuple[str, float]]] = {}
    for s in sensors:
        bits = sensor_bits_per_s(s["model"], float(s["odr_hz"]), loop_hz)
        text = f"{s.get('name', s['model'])} ({s['model']} at {float(s['odr_hz']):g} Hz"
        per_bus.setdefault(int(s["bus"]), []).append((text, bits / bus_hz))
    return [BusLoad(bus, sum(x for _, x in items),
                    tuple(f"{t}: {100 * x:.1f} %)" for t, x in items))
            for bus, items in sorted(per_bus.items())]


def check_bus_loads(sensors: Iterable[Mapping[str, Any]], loop_hz: float,
                    bus_hz: float = BUS_HZ) -> list[str]:
    """Warnings for buses, or all buses together, above :data:`WARN_LOAD` (each with what to
    do).

    Raises
    ------
    InputError
        If a bus would need more than :data:`REFUSE_LOAD` of its bits, or all buses together
        more than the loop's time: the FIFOs must overflow.
    """
    from gyrocal.kit.errors import InputError

    loads = bus_loads(sensors, loop_hz, bus_hz)
    warnings = []
    for b in loads:
        where = (f"I2C bus {b.bus} at {bus_hz / 1000:g} kHz would carry {100 * b.load:.0f} % of "
                 f"its bits ({'; '.join(b.sensors)})")
        advice = ("lower odr_hz, or move sensors to a second I2C bus ([[imu]] bus = N on "
                  "another adapter) if the buses together stay under 100 %")
        if b.load > REFUSE_LOAD:
            raise InputError(f"{where}: more than the bus can, so the FIFOs would overflow and "
                             f"samples be lost; {advice}")
        if b.load > WARN_LOAD:
            warnings.append(f"{where}: above the {100 * WARN_LOAD:.0f} % the emulated bus "
                            f"stayed loss-free at; samples may be lost; {advice}")
    total = sum(b.load for b in loads)
    if len(loads) > 1:
        where = (f"the {len(loads)} I2C buses together would need {100 * total:.0f} % of the "
                 "time gyrocal's loop has (it reads the buses one after the other)")
        advice = ("lower odr_hz: a second bus adds wires, not time, while one loop reads them "
                  "in turn")
        if total > REFUSE_LOAD:
            raise InputError(f"{where}: more than the loop has, so the FIFOs would overflow and "
                             f"samples be lost; {advice}")
        if total > WARN_LOAD:
            warnings.append(f"{where}: above the {100 * WARN_LOAD:.0f} % the emulated buses "
                            f"stayed loss-free at; samples may be lost; {advice}")
    return warnings
