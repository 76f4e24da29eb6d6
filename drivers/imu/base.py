"""What every IMU reader shares: bus access with bounded retries, identification, FIFO streaming,
timestamps, gap reports, saturation and stuck-axis checks.

A reader is used in one loop on one clock::

    reader = MPU9250Reader(bus, 0x68, clock=clock)
    reader.configure(range_dps=500, odr_hz=1000)
    reader.start()
    while running:
        batch = reader.read()          # non-blocking: whatever the FIFO holds now
        ...
    reader.close()

Subclasses supply the chip-specific steps (bring-up, FIFO level, FIFO burst, decoding); the
sample bookkeeping, timestamping and fault handling live here once.
"""

from __future__ import annotations

import errno as errno_mod
import math
import os
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np

from gyrocal.drivers.clock import Clock, SystemClock
from gyrocal.drivers.errors import BusError, ConfigurationError, DeviceIdentityError
from gyrocal.drivers.imu.chips import AccelRange, ChipFamily, ChipModel, GyroRange
from gyrocal.drivers.imu.errors import (
    BusOpenError,
    ChipIdentityError,
    ImuStateError,
    SensorFaultError,
)
from gyrocal.drivers.imu.timing import SampleClock

__all__ = [
    "BLOCK_MAX",
    "ODR_RELATIVE_TOLERANCE",
    "NACK_ERRNOS",
    "TRANSIENT_ERRNOS",
    "ChipNotice",
    "FifoGap",
    "ImuBatch",
    "ImuReader",
    "SensorInfo",
    "TimestampedFifoReader",
    "divided_rate",
    "default_band",
    "filter_band",
    "nearest_rate",
    "open_bus",
]

#: smbus2's I2C_SMBUS_BLOCK_MAX: the longest SMBus block transfer (hardware reference §3).
BLOCK_MAX = 32

#: How far a requested output data rate may be from one the chip can do and still be taken (the
#: chip's rate is used: 333 -> 1000/3 Hz on an MPU-9250, 15 -> 14.9 Hz on an LSM9DS1); farther is
#: refused. ``SensorInfo.odr_hz`` is the rate used, which callers report when it differs.
ODR_RELATIVE_TOLERANCE = 0.01

#: errnos worth retrying (hardware reference §3, "Driver guidance").
TRANSIENT_ERRNOS = frozenset(
    {errno_mod.EREMOTEIO, errno_mod.ENXIO, errno_mod.EIO, errno_mod.ETIMEDOUT, errno_mod.EAGAIN}
)
#: errnos of a NACK: the slave refused its address or the register byte, so no data byte moved and
#: even a FIFO read may simply be repeated. After EIO, ETIMEDOUT or EAGAIN some FIFO bytes may
#: already have been popped, so the reader restarts the FIFO and reports a gap instead.
NACK_ERRNOS = frozenset({errno_mod.EREMOTEIO, errno_mod.ENXIO})
#: errnos of an adapter that cannot do I2C_RDWR (the reader then uses 32-byte block reads).
NO_RDWR_ERRNOS = frozenset({errno_mod.EOPNOTSUPP, errno_mod.ENOTTY, errno_mod.ENOSYS})

_T = TypeVar("_T")


def divided_rate(chip: str, base_hz: float, odr_hz: float, divider: str,
                 examples: tuple[int, ...]) -> tuple[float, int]:
    """The output data rate ``base_hz / (1 + div)`` nearest ``odr_hz`` and its divider
    ``div`` in 0..255 (MPU-9250 register map §4.4 SMPLRT_DIV; ICM-20948 GYRO_SMPLRT_DIV).

    Raises
    ------
    ConfigurationError
        If that rate is more than :data:`ODR_RELATIVE_TOLERANCE` from ``odr_hz`` (the message
        lists rates the chip can do, from the dividers ``examples``).
    """
    div = round(base_hz / odr_hz - 1.0) if odr_hz > 0 else -1
    div = min(max(div, 0), 255)
    actual = base_hz / (1 + div)
    if not (odr_hz > 0 and abs(actual - odr_hz) <= ODR_RELATIVE_TOLERANCE * odr_hz):
        listed = ", ".join(f"{base_hz / (1 + d):.4g}" for d in examples)
        raise ConfigurationError(
            f"odr_hz={odr_hz!r} is not an {chip} output data rate. With the gyro low-pass "
            f"filter on, the rate is {base_hz:g}/(1 + {divider}) Hz for {divider} 0..255, "
            f"that is {listed}, ... down to {base_hz / 256:.4g} Hz."
        )
    return actual, div


def default_band(bands: Iterable[float], odr_hz: float) -> float:
    """The readers' default gyro bandwidth among ``bands``, Hz: the widest below half
    ``odr_hz`` (the narrowest if none is). Below, not at: a filter at half the output rate or
    wider runs ahead of a decimation on the chip and lets the noise above half the rate alias
    in (:func:`gyrocal.drivers.emulated.imu_chips.filter_steps`), which the datasheets' noise
    densities do not include."""
    ordered = sorted(bands, reverse=True)
    return next((b for b in ordered if b < odr_hz / 2), ordered[-1])


def filter_band(chip: str, bands: Iterable[float], lowpass_hz: float | None,
                odr_hz: float) -> float:
    """The gyro low-pass bandwidth, Hz: ``lowpass_hz`` when it is one of ``bands`` (to 0.5 Hz),
    else :func:`default_band`.

    Raises
    ------
    ConfigurationError
        If ``lowpass_hz`` is given and is not one of ``bands`` (the message lists them).
    """
    ordered = sorted(bands, reverse=True)
    if lowpass_hz is None:
        return default_band(ordered, odr_hz)
    lp = next((b for b in ordered if abs(b - float(lowpass_hz)) <= 0.5), None)
    if lp is None:
        raise ConfigurationError(
            f"lowpass_hz={lowpass_hz!r} is not an {chip} gyro filter bandwidth; choose one of "
            + ", ".join(f"{b:g}" for b in ordered) + " Hz"
        )
    return lp


class ChipNotice(UserWarning):
    """A chip was accepted with a caveat the user should know (e.g. an MPU-6500)."""


def open_bus(bus: int | str) -> Any:
    """Open ``/dev/i2c-<bus>`` (or the path ``bus``) with smbus2.

    Parameters
    ----------
    bus : int or str
        The adapter number (``1`` on a Raspberry Pi) or a device path.

    Returns
    -------
    smbus2.SMBus
        The open bus.

    Raises
    ------
    BusOpenError
        If the device file is missing or not accessible, with what to do about it.
    """
    import smbus2

    path = f"/dev/i2c-{bus}" if isinstance(bus, int) else str(bus)
    try:
        return smbus2.SMBus(bus)
    except FileNotFoundError as e:
        raise BusOpenError(
            f"{path} does not exist, so I²C is not enabled or the adapter number is wrong. On a "
            "Raspberry Pi enable I²C with `sudo raspi-config` (Interface Options → I2C) or add "
            "`dtparam=i2c_arm=on` to /boot/firmware/config.txt (/boot/config.txt on older "
            "systems) and reboot; the header pins 3/5 are bus 1. Elsewhere load the driver with "
            "`sudo modprobe i2c-dev` and list the adapters with `i2cdetect -l`.",
            errno=e.errno,
        ) from e
    except PermissionError as e:
        raise BusOpenError(
            f"permission denied opening {path}. Add your user to the `i2c` group "
            "(`sudo usermod -aG i2c $USER`), then log out and in again; do not run gyrocal as "
            "root.",
            errno=e.errno,
        ) from e
    except OSError as e:
        raise BusOpenError(f"cannot open {path}: {e}", errno=e.errno) from e


@dataclass(frozen=True)
class SensorInfo:
    """What a configured reader tells the Recording v1 manifest and the report.

    Parameters
    ----------
    model : str
        ``"mpu9250"``, ``"mpu9255"``, ``"mpu6500"`` or ``"lsm9ds1"``.
    odr_hz : float
        The output data rate the chip was set to (its nominal value; the chip's own clock may
        differ, see :attr:`ImuReader.measured_odr_hz`).
    full_scale_dps : float
        The configured gyro range, ± °/s.
    sensitivity_rad_s_per_lsb : float
        The datasheet sensitivity applied to the raw counts.
    lowpass_hz : float
        The gyro low-pass bandwidth.
    address : int
        The 7-bit I²C address.
    who_am_i : int
        The identity byte read from the chip.
    accel_full_scale_g : float or None
        The configured accelerometer range, ± g (None for a reader without the accelerometer).
    accel_sensitivity_m_s2_per_lsb : float or None
        The accelerometer's datasheet sensitivity times standard gravity, m/s² per count.
    """

    model: str
    odr_hz: float
    full_scale_dps: float
    sensitivity_rad_s_per_lsb: float
    lowpass_hz: float
    address: int
    who_am_i: int
    accel_full_scale_g: float | None = None
    accel_sensitivity_m_s2_per_lsb: float | None = None

    def manifest(self) -> dict[str, Any]:
        """The ``"sensor"`` object of a Recording v1 manifest (with the accelerometer's range
        and sensitivity when it is recorded)."""
        out: dict[str, Any] = {
            "model": self.model,
            "odr_hz": self.odr_hz,
            "full_scale_dps": self.full_scale_dps,
            "sensitivity_rad_s_per_lsb": self.sensitivity_rad_s_per_lsb,
        }
        if self.accel_sensitivity_m_s2_per_lsb is not None:
            out["accel_full_scale_g"] = self.accel_full_scale_g
            out["accel_sensitivity_m_s2_per_lsb"] = self.accel_sensitivity_m_s2_per_lsb
        return out


@dataclass(frozen=True)
class FifoGap:
    """Samples the chip produced that the reader could not deliver.

    Parameters
    ----------
    t : float
        Reconstructed time of the first lost sample, on the caller's clock.
    t_end : float
        Reconstructed time of the last lost sample.
    samples : int
        How many samples were lost (estimated from the chip clock model, typically exact and
        at worst one off).
    first_index : int
        Stream index of the first lost sample.
    reason : str
        ``"fifo overflow"`` or a description of the bus error that forced a FIFO restart.
    """

    t: float
    t_end: float
    samples: int
    first_index: int
    reason: str


@dataclass(frozen=True)
class ImuBatch:
    """The samples one :meth:`ImuReader.read` drained.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times in seconds on the caller's clock.
    rate : ndarray, shape (N, 3)
        Angular rate in rad/s: raw counts times the datasheet sensitivity, nothing else (no
        bias or scale correction).
    temperature_c : ndarray, shape (N,)
        Chip temperature in °C.
    saturated : ndarray, shape (N, 3), bool
        True where an axis was at or near full scale.
    raw_counts : ndarray, shape (N, 3), int16
        The gyro counts as read.
    index : ndarray, shape (N,), int64
        Stream index of each sample (consecutive except across gaps).
    accel : ndarray, shape (N, 3)
        Specific force in m/s², sensor frame, from the same FIFO sample: raw counts times the
        datasheet sensitivity (:class:`~gyrocal.drivers.imu.chips.AccelRange`) times standard
        gravity, nothing else.
    accel_saturated : ndarray, shape (N, 3), bool
        True where an accelerometer axis was at or near its full scale.
    gaps : tuple of FifoGap
        Samples lost since the previous batch.
    """

    t: np.ndarray
    rate: np.ndarray
    temperature_c: np.ndarray
    saturated: np.ndarray
    raw_counts: np.ndarray
    index: np.ndarray
    accel: np.ndarray
    accel_saturated: np.ndarray
    gaps: tuple[FifoGap, ...] = field(default=())

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @classmethod
    def empty(cls, gaps: tuple[FifoGap, ...] = ()) -> ImuBatch:
        """A batch with no samples (and possibly gaps)."""
        return cls(
            t=np.empty(0),
            rate=np.empty((0, 3)),
            temperature_c=np.empty(0),
            saturated=np.zeros((0, 3), dtype=bool),
            raw_counts=np.empty((0, 3), dtype=np.int16),
            index=np.empty(0, dtype=np.int64),
            accel=np.empty((0, 3)),
            accel_saturated=np.zeros((0, 3), dtype=bool),
            gaps=gaps,
        )


def _hex(v: int | None) -> str:
    return "none" if v is None else f"0x{v:02X}"


def _bus_error_reason(e: OSError, during: str) -> str:
    """The reason of a gap forced by a bus error."""
    return f"bus error {during} ([Errno {e.errno}] {os.strerror(e.errno or 0)}); FIFO restarted"


class ImuReader(ABC):
    """Base of the chip readers.

    Parameters
    ----------
    bus : smbus2.SMBus-like, int or str
        Any object with smbus2's ``read_byte_data``, ``write_byte_data``,
        ``read_i2c_block_data`` and optionally ``i2c_rdwr``; or an adapter number or device path,
        which the reader opens (and closes on :meth:`close`) itself.
    address : int, optional
        7-bit I²C address; the family's default when omitted.
    clock : Clock, optional
        The clock timestamps are taken on and waits are spent on; :class:`SystemClock` when
        omitted.
    retries : int
        Transient bus errors are retried this many times before :class:`BusError`.
    retry_delay_s : float
        Wait between retries.
    saturation_fraction : float
        A sample whose |counts| reach this fraction of the int16 full scale (32768) is flagged
        saturated.
    stuck_after_s : float or None
        An axis whose raw counts stay exactly constant (and not saturated) for this long, and
        for at least ``stuck_min_samples`` samples, raises :class:`SensorFaultError`. A live
        gyro's noise always moves its low bits. The samples read before the run reached that
        length have been delivered already. ``None`` disables the check.
    stuck_min_samples : int
        See ``stuck_after_s``.
    discard_first : bool
        Drop the first sample after each FIFO (re)start, as the datasheets advise.
    clock_fit_window_s : float
        Window of the sample-time fit (:class:`~gyrocal.drivers.imu.timing.SampleClock`).
    """

    family: ClassVar[ChipFamily]
    #: After an overflow the FIFO holds the oldest samples (stop when full), which continue the
    #: stream and are delivered; otherwise it holds the newest, whose sample numbers cannot be
    #: known exactly, and they are dropped with the gap.
    overflow_keeps_oldest: ClassVar[bool] = True
    #: The FIFO's packets carry the chip's sample timestamps, from which :meth:`_stream_index`
    #: numbers the samples exactly, also after a restart: the clock fit then needs no new
    #: segment there (see :meth:`_restart`).
    numbers_from_timestamps: ClassVar[bool] = False

    def __init__(
        self,
        bus: Any,
        address: int | None = None,
        *,
        clock: Clock | None = None,
        retries: int = 3,
        retry_delay_s: float = 0.002,
        saturation_fraction: float = 0.98,
        stuck_after_s: float | None = 1.0,
        stuck_min_samples: int = 200,
        discard_first: bool = True,
        clock_fit_window_s: float = 5.0,
    ) -> None:
        if address is None:
            address = self.family.addresses[0]
        if not isinstance(address, int) or not 0x03 <= address <= 0x77:
            raise ConfigurationError(
                f"address must be a 7-bit I²C address (0x03..0x77), got {address!r}; the "
                f"{self.family.title} answers at "
                + " or ".join(_hex(a) for a in self.family.addresses)
            )
        if not isinstance(retries, int) or retries < 0:
            raise ConfigurationError(f"retries must be a non-negative integer, got {retries!r}")
        if not 0.5 < saturation_fraction <= 1.0:
            raise ConfigurationError(
                f"saturation_fraction must be in (0.5, 1], got {saturation_fraction!r}"
            )
        self._owns_bus = isinstance(bus, (int, str))
        self._bus = open_bus(bus) if self._owns_bus else bus
        #: How to scan this bus for the advice in error messages.
        self._scan_hint = f"`i2cdetect -y {bus}`" if isinstance(bus, int) else (
            "`i2cdetect -l` for the bus number, then `i2cdetect -y N`")
        self.address = address
        self._clock: Clock = clock if clock is not None else SystemClock()
        self.retries = retries
        self.retry_delay_s = float(retry_delay_s)
        self._sat_counts = int(math.floor(saturation_fraction * 32768))
        self.stuck_after_s = stuck_after_s
        self.stuck_min_samples = int(stuck_min_samples)
        self.discard_first = bool(discard_first)
        self.clock_fit_window_s = float(clock_fit_window_s)
        self._rdwr = callable(getattr(self._bus, "i2c_rdwr", None))
        #: ``i2c_rdwr`` messages of :meth:`_burst` by (register, length).
        self._burst_msgs: dict[tuple[int, int], tuple[Any, Any]] = {}
        self._info: SensorInfo | None = None
        self._streaming = False
        self._closed = False
        self.notice: str | None = None
        self.samples_delivered = self.samples_lost = self.gap_count = 0  # counted from start()
        try:
            self.chip: ChipModel = self._identify()
        except BaseException:
            self._close_bus()
            raise

    # -- bus access ---------------------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        """The clock timestamps are taken on."""
        return self._clock

    @property
    def uses_i2c_rdwr(self) -> bool:
        """Whether long FIFO bursts go through ``i2c_rdwr`` (else 32-byte block reads)."""
        return self._rdwr

    def _reg_name(self, register: int | None) -> str:
        if register is None:
            return ""
        regs = self._register_names()
        name = regs.get(register)
        return f"{_hex(register)} ({name})" if name else _hex(register)

    @abstractmethod
    def _register_names(self) -> dict[int, str]:
        """Register address → name, for messages."""

    def _bus_error(self, e: OSError, register: int | None, attempts: int) -> BusError:
        code = e.errno
        what = os.strerror(code) if code else str(e)
        return BusError(
            f"I²C error talking to the {self.family.title} at {_hex(self.address)}, register "
            f"{self._reg_name(register)}: [Errno {code}] {what}, after {attempts} attempt(s). "
            "Check the wiring (SDA, SCL, GND, 3.3 V), the address (" + self._scan_hint + "), the "
            "pull-ups and the cable length; the bus may need a slower clock.",
            errno=code,
            address=self.address,
            register=register,
        )

    def _xfer(self, register: int | None, fn: Callable[[], _T], *, retry: bool = True) -> _T:
        """Run one bus transfer, retrying transient errors; raise :class:`BusError` when it fails.

        With ``retry=False`` only NACKs (nothing moved) are retried and any other transient
        error is re-raised as ``OSError`` for the caller to handle.
        """
        attempt = 0
        while True:
            attempt += 1
            try:
                return fn()
            except OSError as e:
                transient = e.errno in TRANSIENT_ERRNOS
                if transient and not retry and e.errno not in NACK_ERRNOS:
                    raise
                if not transient or attempt > self.retries:
                    raise self._bus_error(e, register, attempt) from e
                self._clock.sleep(self.retry_delay_s)

    def _read_byte(self, register: int, *, retry: bool = True) -> int:
        return int(
            self._xfer(
                register, lambda: self._bus.read_byte_data(self.address, register), retry=retry
            )
        )

    def _write_byte(self, register: int, value: int) -> None:
        self._xfer(register, lambda: self._bus.write_byte_data(self.address, register, value))

    def _read_block(self, register: int, length: int) -> bytes:
        return bytes(
            self._xfer(
                register, lambda: self._bus.read_i2c_block_data(self.address, register, length)
            )
        )

    def _burst(self, register: int, length: int) -> bytes:
        """One long read starting at ``register`` through ``i2c_rdwr`` (write reg, read N)."""
        msgs = self._burst_msgs.get((register, length))
        if msgs is None:  # made once per register and length: the kernel copies them each time
            from smbus2 import i2c_msg

            if len(self._burst_msgs) > 64:
                self._burst_msgs.clear()
            msgs = self._burst_msgs[register, length] = (
                i2c_msg.write(self.address, [register]), i2c_msg.read(self.address, length))
        self._bus.i2c_rdwr(*msgs)
        return bytes(msgs[1])

    def _read_stream(self, register: int, length: int, chunk: int) -> bytes:
        """Read ``length`` bytes from a FIFO data port (or a wrapping register window) at
        ``register``: one ``i2c_rdwr`` burst where the bus has it, else block reads of ``chunk``
        bytes (a multiple of the frame size, at most 32). NACKs are retried; other transient
        errors propagate as ``OSError`` because bytes may already have left the FIFO.
        """
        if self._rdwr:
            try:
                return self._xfer(register, lambda: self._burst(register, length), retry=False)
            except BusError as e:
                if e.errno not in NO_RDWR_ERRNOS:
                    raise
                self._rdwr = False  # the adapter cannot do I2C_RDWR: use block reads from now on
        out = bytearray()
        while len(out) < length:
            n = min(chunk, length - len(out))
            out += self._xfer(
                register,
                lambda n=n: bytes(self._bus.read_i2c_block_data(self.address, register, n)),
                retry=False,
            )
        return bytes(out)

    # -- identity -----------------------------------------------------------------------------

    def _identify(self) -> ChipModel:
        """Read WHO_AM_I and accept the chip, or explain what is there instead."""
        fam = self.family
        try:
            who = self._read_byte(fam.who_am_i_register)
        except BusError as e:
            raise BusError(
                f"no answer from {_hex(self.address)} on the I²C bus while looking for the "
                f"{fam.title} ([Errno {e.errno}] {os.strerror(e.errno or 0)}). Check the wiring "
                "and power, and list the devices that answer with " + self._scan_hint + "; the "
                f"{fam.title} answers at " + " or ".join(_hex(a) for a in fam.addresses) + ".",
                errno=e.errno,
                address=self.address,
                register=fam.who_am_i_register,
            ) from e
        model = fam.model_for(who)
        if model is not None:
            if model.notice:
                self.notice = model.notice
                warnings.warn(model.notice, ChipNotice, stacklevel=3)
            return model
        expected = ", ".join(f"{_hex(m.who_am_i)} ({m.title})" for m in fam.models)
        what = fam.siblings.get(who)
        if what is None:
            what = self._probe_other_families()
        msg = (
            f"the chip at {_hex(self.address)} answered WHO_AM_I {_hex(who)} at register "
            f"{_hex(fam.who_am_i_register)}; the {fam.title} reader expects {expected}."
        )
        if what:
            msg += f" That is {what}."
        else:
            msg += " Check the address and the board."
        raise ChipIdentityError(msg, address=self.address, who_am_i=who)

    def _probe_other_families(self) -> str | None:
        """Name a chip of another supported family at this address, read-only, if one is there."""
        from gyrocal.drivers.imu import READERS

        for other in {cls.family.name: cls.family for cls in READERS.values()}.values():
            if other is self.family:
                continue
            try:
                who = self._read_byte(other.who_am_i_register)
            except BusError:
                continue
            m = other.model_for(who)
            if m is not None:
                return (
                    f"an {m.title} (WHO_AM_I {_hex(who)} at register "
                    f"{_hex(other.who_am_i_register)}); use model '{m.name}'"
                )
        return None

    def _check_identity_again(self) -> None:
        """After a reset, the chip must still be the one identified."""
        who = self._read_byte(self.family.who_am_i_register)
        if who != self.chip.who_am_i:
            raise ChipIdentityError(
                f"after reset the chip at {_hex(self.address)} answered WHO_AM_I {_hex(who)}, "
                f"not {_hex(self.chip.who_am_i)} as before: the bus or the chip is unreliable.",
                address=self.address,
                who_am_i=who,
            )

    def _verify(self, register: int, expected: int) -> None:
        got = self._read_byte(register)
        if got != expected:
            raise DeviceIdentityError(
                f"wrote {_hex(expected)} to register {self._reg_name(register)} of the "
                f"{self.chip.title} at {_hex(self.address)} but read back {_hex(got)}: the chip "
                "does not behave like a genuine part (counterfeit or damaged?) or the bus "
                "corrupts data."
            )

    # -- configuration ------------------------------------------------------------------------

    @property
    def model(self) -> str:
        """The identified chip's model name (``"mpu9250"``, ``"mpu6500"``, ``"lsm9ds1"``...)."""
        return self.chip.name

    @property
    def info(self) -> SensorInfo:
        """The configured sensor's facts; raises :class:`ImuStateError` before configure()."""
        if self._info is None:
            raise ImuStateError("the reader is not configured yet: call configure() first")
        return self._info

    @property
    def odr_hz(self) -> float:
        """Configured output data rate (nominal)."""
        return self.info.odr_hz

    @property
    def full_scale_dps(self) -> float:
        """Configured gyro range, ± °/s."""
        return self.info.full_scale_dps

    @property
    def sensitivity_rad_s_per_lsb(self) -> float:
        """Datasheet sensitivity for the configured range."""
        return self.info.sensitivity_rad_s_per_lsb

    @property
    def measured_odr_hz(self) -> float | None:
        """The chip's output data rate measured on the host clock while streaming, or ``None``."""
        return None if not self._streaming else 1.0 / self._sclock.period_s

    def _choose_range(self, range_dps: float) -> GyroRange:
        r = self.family.range_for(float(range_dps))
        if r is None:
            offered = ", ".join(f"{g.full_scale_dps:g}" for g in self.family.gyro_ranges)
            raise ConfigurationError(
                f"range_dps={range_dps!r} is not a {self.family.title} gyro range; choose one of "
                f"{offered} (± °/s)"
            )
        return r

    @property
    def accel_range(self) -> AccelRange:
        """The accelerometer range :meth:`configure` sets (the family's, as data)."""
        return self.family.accel_range

    @classmethod
    @abstractmethod
    def offered_rates_hz(cls) -> tuple[float, ...]:
        """Every output data rate the reader can configure, Hz, ascending (from the chip's
        tables in :mod:`gyrocal.drivers.imu.chips`)."""

    @abstractmethod
    def _choose_rate(self, odr_hz: float, lowpass_hz: float | None) -> tuple[float, float, Any]:
        """Validate the rate and filter: return (odr_hz, lowpass_hz, chip setting)."""

    @abstractmethod
    def _bring_up(self, rng: GyroRange, setting: Any) -> None:
        """Reset, wake, check identity again, write the configuration, wait for start-up."""

    def configure(
        self, range_dps: float, odr_hz: float, lowpass_hz: float | None = None
    ) -> SensorInfo:
        """Bring the chip up and configure its gyro (hardware reference §1.3–1.5 / §2.3–2.6).

        Parameters
        ----------
        range_dps : float
            Gyro full scale, ± °/s; one the chip offers (the error lists them).
        odr_hz : float
            Output data rate; one the chip offers (within 1 %; the error lists them).
        lowpass_hz : float, optional
            Gyro low-pass bandwidth; one the chip offers at that rate. By default the widest
            bandwidth below half the rate (:func:`default_band`).

        Returns
        -------
        SensorInfo
            What was configured.

        Raises
        ------
        ConfigurationError
            For a range, rate or filter the chip cannot do.
        BusError, DeviceIdentityError
            If the chip fails to answer or to take the settings.
        """
        self._require_open()
        if self._streaming:
            self.stop()
        rng = self._choose_range(range_dps)
        odr, lp, setting = self._choose_rate(float(odr_hz), lowpass_hz)
        self._bring_up(rng, setting)
        acc = self.accel_range
        self._info = SensorInfo(
            model=self.chip.name,
            odr_hz=odr,
            full_scale_dps=rng.full_scale_dps,
            sensitivity_rad_s_per_lsb=rng.sensitivity_rad_s_per_lsb,
            lowpass_hz=lp,
            address=self.address,
            who_am_i=self.chip.who_am_i,
            accel_full_scale_g=acc.full_scale_g,
            accel_sensitivity_m_s2_per_lsb=acc.sensitivity_m_s2_per_lsb,
        )
        return self._info

    # -- streaming ----------------------------------------------------------------------------

    @abstractmethod
    def _fifo_prepare(self) -> None:
        """Stop and empty the FIFO and set what it collects, short of enabling it."""

    @abstractmethod
    def _fifo_go(self) -> None:
        """The single register write that starts FIFO collection."""

    @abstractmethod
    def _disable_fifo(self) -> None:
        """Stop the FIFO."""

    @abstractmethod
    def _fifo_level(self) -> tuple[int, bool, float]:
        """Read the FIFO level: (whole samples available, overflow flagged, clock time just
        after the transfer that latched the level)."""

    @abstractmethod
    def _overflowed(self) -> bool:
        """Whether the chip reports a lost sample now (asked after each burst).

        A chip whose flag clears when read lets transient errors other than NACKs propagate as
        ``OSError``: the failed read may have cleared the flag, so a retry could not be trusted.
        """

    @abstractmethod
    def _fifo_read(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Pop ``n`` samples: gyro counts (n, 3) int16, accelerometer counts (n, 3) int16 of
        the same samples, and temperature counts (n,) or ``None``.

        Transient errors other than NACKs propagate as ``OSError``.
        """

    @abstractmethod
    def _temperature_counts(self) -> int:
        """Read the temperature register now (for chips without temperature in the FIFO)."""

    @abstractmethod
    def _power_down(self) -> None:
        """Put the chip to sleep."""

    def start(self) -> None:
        """Start streaming through the FIFO; the stream's sample indices start at 0."""
        self._require_open()
        if self._info is None:
            raise ImuStateError("configure() the reader before start()")
        if self._streaming:
            return
        self._sclock = SampleClock(1.0 / self._info.odr_hz, window_s=self.clock_fit_window_s)
        self.samples_delivered = self.samples_lost = self.gap_count = 0
        self._next_index = 0
        self._discard_pending = self.discard_first
        self._pending_gap: tuple[int, str] | None = None  # (first lost, reason), see _restart
        self._last_t = -math.inf
        self._run_value = np.zeros(3, dtype=np.int32)  # last counts of each axis
        self._run_length = np.zeros(3, dtype=np.int64)  # how many samples they have lasted
        self._fifo_prepare()
        t_b = self._clock.monotonic()
        self._fifo_go()
        self._sclock.observe(t_b, self._clock.monotonic(), 0)
        self._streaming = True

    @property
    def streaming(self) -> bool:
        """Whether :meth:`start` has been called and :meth:`stop` has not."""
        return self._streaming

    def read(self) -> ImuBatch:
        """Drain the FIFO now and return its samples (non-blocking; may be empty).

        Returns
        -------
        ImuBatch
            Times on the caller's clock, rates in rad/s (datasheet sensitivity only), °C,
            saturation flags, and any gaps (FIFO overflow, or a bus error in mid-burst or
            while reading a clear-on-read overflow flag, which forced a FIFO restart).

        Raises
        ------
        BusError
            A persistent bus error (after bounded retries).
        SensorFaultError
            An axis is stuck.
        ImuStateError
            If the reader is not streaming.
        """
        if not self._streaming:
            raise ImuStateError("the reader is not streaming: call configure() and start() first")
        t_b = self._clock.monotonic()
        n, overflow, t_a = self._fifo_level()
        lost = "fifo overflow" if overflow else None  # why samples were lost, if they were
        if lost and not self.overflow_keeps_oldest:
            return ImuBatch.empty(self._restart(self._next_index, lost))
        gyro = accel = np.empty((0, 3), dtype=np.int16)
        temp: np.ndarray | None = None
        if n:
            try:
                gyro, accel, temp = self._fifo_read(n)
            except OSError as e:
                reason = _bus_error_reason(e, "during FIFO read")
                return ImuBatch.empty(self._restart(self._next_index, reason))
            # A sample can be lost while the burst runs, too: ask the chip again.
            late = self._late_overflow()
            if late and not self.overflow_keeps_oldest:
                # the oldest unread slot was overwritten before the burst reached it, so the
                # slots just read do not follow the last batch: drop them with the gap
                return ImuBatch.empty(self._restart(self._next_index, late))
            lost = lost or late
        index = self._stream_index(n)
        jumps = self._jump_gaps(index)
        if n:
            self._next_index = int(index[-1]) + 1
        if lost is None:
            self._sclock.observe(t_b, t_a, self._next_index)
        if temp is None:
            temp = np.full(n, self._temperature_counts() if n else 0, dtype=np.float64)
        if self._discard_pending and n:
            gyro, accel, temp, index = gyro[1:], accel[1:], temp[1:], index[1:]
            self._discard_pending = False
        gaps: tuple[FifoGap, ...] = jumps
        if lost:
            # a full FIFO that keeps its oldest samples drops only newer ones: the samples
            # just read follow the last batch, and the loss comes after them
            gaps += self._restart(self._next_index, lost)
        return self._make_batch(index, gyro, accel, temp, gaps)

    def _stream_index(self, n: int) -> np.ndarray:
        """Stream indices of the ``n`` samples just popped: consecutive from the next expected.

        A reader whose FIFO packets carry the chip's own sample timestamps (ICM-42688-P)
        numbers them from the timestamps instead; a jump is then a gap of known size.
        """
        return np.arange(self._next_index, self._next_index + n, dtype=np.int64)

    def _jump_gaps(self, index: np.ndarray) -> tuple[FifoGap, ...]:
        """Gaps where ``index`` skips samples (only readers with timestamps can see them),
        including the loss of a FIFO restart, now of known size (see :meth:`_restart`).

        The first sample after a restart is dropped (``discard_first``) and counted in the
        restart's gap.
        """
        if index.size == 0:
            return ()
        start = self._next_index
        if self._pending_gap is None and not self.numbers_from_timestamps:
            return ()  # numbered consecutively from the next expected (_stream_index): no skip
        gaps = []
        if self._pending_gap is not None:
            first, reason = self._pending_gap
            self._pending_gap = None
            start = int(index[0])
            lost = start - first + (1 if self._discard_pending else 0)
            if lost > 0:
                gaps.append(self._gap(first, lost, reason))
        starts = np.concatenate(([start], index[:-1] + 1))
        skipped = index - starts
        jump = "samples missing from the FIFO stream (the chip's timestamps jump)"
        gaps += [self._gap(int(starts[i]), int(skipped[i]), jump)
                 for i in np.flatnonzero(skipped > 0)]
        return tuple(gaps)

    def _late_overflow(self) -> str | None:
        """Ask the chip after a burst whether samples were lost: the gap's reason, or ``None``."""
        try:
            return "fifo overflow" if self._overflowed() else None
        except OSError as e:
            # the flag clears when read, and the failed read may have cleared it: an overflow
            # cannot be ruled out, so the FIFO is restarted as after one
            return _bus_error_reason(e, "reading the FIFO overflow flag")

    def _restart(self, first_lost: int, reason: str) -> tuple[FifoGap, ...]:
        """Restart the FIFO after data were lost and report the gap.

        The chip keeps sampling on its own grid while its FIFO is reset, so the first sample
        collected after the restart is the first grid point after the enabling write. The write
        is timed just after a predicted sample instant, so that the number of samples produced
        by then is known exactly from the fitted grid rather than guessed to within one; a write
        that still straddles a sample instant is done again. Where the fit is weak (restarts
        at nearly every drain) the count can still be a sample off, so the clock fit starts a
        new segment there and re-learns its offset rather than bend its period.
        """
        clock, sc = self._clock, self._sclock
        margin = 0.25 * sc.period_s
        for _ in range(3):
            self._fifo_prepare()
            now = clock.monotonic()
            next_tick = float(sc.time_of(sc.count_at(now)))
            clock.sleep(max(0.0, next_tick + margin - now))
            t_b = clock.monotonic()
            self._fifo_go()
            t_a = clock.monotonic()
            if sc.count_at(t_b - margin) == sc.count_at(t_a + margin):
                break
        if self._discard_pending:
            # that sample is accounted for already: in the last restart's gap, or as the one
            # dropped by design at the start
            first_lost += 1
        produced = max(sc.count_at(0.5 * (t_b + t_a)), first_lost)
        self._next_index = produced
        if self.numbers_from_timestamps:
            # the first sample's timestamp will tell exactly how many were lost: the gap is
            # reported with the batch that brings it (see _jump_gaps), and the clock fit needs
            # no new segment; produced is only the estimate that resolves a timestamp's wrap
            if self._pending_gap is None:
                self._pending_gap = (first_lost, reason)
            self._discard_pending = self.discard_first
            return ()
        sc.new_segment(produced)  # a miscount here must not bend the period fit
        lost = produced - first_lost
        if self.discard_first:
            self._discard_pending = True
            lost += 1  # the first sample after the restart is dropped too
        return (self._gap(first_lost, lost, reason),)

    def _gap(self, first: int, samples: int, reason: str) -> FifoGap:
        self.samples_lost += samples
        self.gap_count += 1
        times = self._sclock.time_of(np.array([first, first + max(samples, 1) - 1]))
        return FifoGap(
            t=float(times[0]), t_end=float(times[1]), samples=samples, first_index=first,
            reason=reason,
        )

    def _make_batch(
        self, index: np.ndarray, gyro: np.ndarray, accel: np.ndarray, temp_counts: np.ndarray,
        gaps: tuple,
    ) -> ImuBatch:
        if index.size == 0:
            return ImuBatch.empty(gaps)
        # gyro and accelerometer counts side by side in native int32 (the FIFO's words may be
        # big-endian views): one conversion, one saturation test and one scaling for both, as a
        # drain of a sample or two is mostly the per-call cost of numpy
        wide = np.concatenate((gyro, accel), axis=1, dtype=np.int32)
        saturated = np.abs(wide) >= self._sat_counts
        scaled = wide * self._scale6
        self._check_stuck(wide[:, :3], saturated[:, :3])
        temperature = self.family.counts_to_celsius(temp_counts)
        t = self._sclock.time_of(index)
        if t[0] <= self._last_t:  # a refit moved the line back a hair: keep time increasing
            t = np.maximum(t, self._last_t + 0.5 * self._sclock.period_s)
        self._last_t = float(t[-1])
        self.samples_delivered += index.size
        return ImuBatch(
            t=t,
            rate=scaled[:, :3],
            temperature_c=temperature,
            saturated=saturated[:, :3],
            raw_counts=gyro.astype(np.int16, copy=False),
            index=index,
            accel=scaled[:, 3:],
            accel_saturated=saturated[:, 3:],
            gaps=gaps,
        )

    @property
    def _scale6(self) -> np.ndarray:
        """Per column of :meth:`_make_batch`'s counts: the gyro's sensitivity (rad/s) thrice,
        the accelerometer's (m/s²) thrice."""
        key = (self.info.sensitivity_rad_s_per_lsb, self.accel_range.sensitivity_m_s2_per_lsb)
        if getattr(self, "_scale6_key", None) != key:
            self._scale6_key = key
            self._scale6_cache = np.repeat(np.asarray(key, dtype=np.float64), 3)
        return self._scale6_cache

    def _check_stuck(self, counts: np.ndarray, saturated: np.ndarray) -> None:
        """Track runs of identical counts per axis; raise when one is long enough to be stuck."""
        if self.stuck_after_s is None:
            return
        limit = max(self.stuck_min_samples, math.ceil(self.stuck_after_s * self.info.odr_hz))
        n = counts.shape[0]
        if n == 1:  # the usual drain at a fast loop: the same bookkeeping, without the arrays
            row, last, runs = counts[0].tolist(), self._run_value.tolist(), self._run_length
            for axis in range(3):
                if runs[axis] + 1 >= limit:
                    self._find_stuck_run(counts[:, axis], saturated[:, axis], axis, limit)
                runs[axis] = runs[axis] + 1 if row[axis] == last[axis] else 1
            self._run_value = counts[-1].copy()
            return
        same_as_before = counts == np.vstack((self._run_value[None, :], counts[:-1]))
        for axis in range(3):
            col = same_as_before[:, axis]
            if self._run_length[axis] + n >= limit:
                self._find_stuck_run(counts[:, axis], saturated[:, axis], axis, limit)
            changes = np.flatnonzero(~col)
            if changes.size:
                self._run_length[axis] = n - changes[-1]
            else:
                self._run_length[axis] += n
        self._run_value = counts[-1].copy()

    def _find_stuck_run(
        self, col: np.ndarray, saturated: np.ndarray, axis: int, limit: int
    ) -> None:
        n = col.shape[0]
        starts = np.concatenate(([0], np.flatnonzero(col[1:] != col[:-1]) + 1))
        lengths = np.diff(np.concatenate((starts, [n])))
        if col[0] == self._run_value[axis]:
            lengths[0] += self._run_length[axis]
        bad = (lengths >= limit) & ~saturated[starts]
        if np.any(bad):
            v = int(col[starts[np.argmax(bad)]])
            raise SensorFaultError(
                f"gyro axis {'xyz'[axis]} of the {self.chip.title} at {_hex(self.address)} has "
                f"given exactly {v} counts for {limit} samples or more: the axis is stuck (a live "
                "gyro's noise always moves its low bits). Power-cycle the sensor; if it persists "
                "the part is damaged.",
                axis=axis,
            )

    def stop(self) -> None:
        """Stop streaming (the FIFO is disabled; the configuration is kept)."""
        if self._streaming:
            self._streaming = False
            self._disable_fifo()

    def close(self) -> None:
        """Stop streaming, put the chip to sleep, and close the bus if the reader opened it."""
        if self._closed:
            return
        self._closed = True
        try:
            self.stop()
            self._power_down()
        finally:
            self._close_bus()

    def _close_bus(self) -> None:
        if self._owns_bus:
            self._bus.close()

    def _require_open(self) -> None:
        if self._closed:
            raise ImuStateError("the reader is closed")

    def __enter__(self) -> ImuReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(model={self.chip.name!r}, address={_hex(self.address)})"



class TimestampedFifoReader(ImuReader):
    """Base of the readers whose FIFO packets carry the chip's sample timestamps
    (ICM-42688-P, LSM6DSOX): the samples are numbered from the timestamps, so a jump is a gap
    of exactly known size and the first sample after a FIFO restart has an exact number.

    Consecutive samples are one nominal period apart on the timestamp counter (both run on the
    chip's oscillator). A counter that wraps within a run (the ICM-42688-P's 16 bits at 16 µs,
    1.05 s) is unwrapped with the host-clock estimate of the sample number, which is good to
    far better than half a wrap. Sample times on the host clock then follow from the numbers by
    the shared timing model (:class:`~gyrocal.drivers.imu.timing.SampleClock`): the timestamps
    count the chip's oscillator, not the host's, so they number the samples but do not time
    them.

    Subclasses set :attr:`timestamp_tick_s` and :attr:`timestamp_modulus` (chip data) and
    leave the popped packets' timestamps in ``self._stamps`` in :meth:`_fifo_read`.
    """

    numbers_from_timestamps = True
    #: Seconds per timestamp count.
    timestamp_tick_s: ClassVar[float]
    #: The counter's modulus (2^16, 2^32).
    timestamp_modulus: ClassVar[int]
    #: Register that selects a user bank or page, readable in all of them, and the mask of its
    #: value that means "not the main bank": a chip left there by an earlier program answers
    #: something else at WHO_AM_I, and the reader goes back to the main bank and asks again.
    bank_register: ClassVar[int]
    bank_mask: ClassVar[int]

    def __init__(self, bus: Any, address: int | None = None, **kwargs: Any) -> None:
        self._stamps = np.empty(0, dtype=np.int64)
        self._stamp_ref: tuple[int, int] | None = None  # (timestamp, index) of the last sample
        super().__init__(bus, address, **kwargs)

    def _identify(self) -> ChipModel:
        from gyrocal.drivers.imu.errors import ChipIdentityError

        try:
            return super()._identify()
        except ChipIdentityError:
            if not self._read_byte(self.bank_register) & self.bank_mask:
                raise
            self._write_byte(self.bank_register, 0)  # left in another bank: back to the main one
            return super()._identify()

    @property
    def period_ticks(self) -> float:
        """The configured sample period in timestamp counts."""
        return 1.0 / (self.info.odr_hz * self.timestamp_tick_s)

    def start(self) -> None:
        """Start streaming; the sample numbering (from the timestamps) starts afresh."""
        if not self._streaming:
            self._stamp_ref = None
        super().start()

    def _stream_index(self, n: int) -> np.ndarray:
        """Sample numbers from the packets' timestamps (see the class docstring)."""
        if n == 0:
            return np.empty(0, dtype=np.int64)
        p, stamps, mod = self.period_ticks, self._stamps, self.timestamp_modulus
        steps = np.maximum(1, np.rint((np.diff(stamps) % mod) / p).astype(np.int64))
        if self._stamp_ref is None:
            first = self._next_index
        else:
            ref_stamp, ref_index = self._stamp_ref
            ticks = (int(stamps[0]) - ref_stamp) % mod
            expected = (self._next_index - ref_index) * p  # from the host-clock estimate
            ticks += round((expected - ticks) / mod) * mod
            first = ref_index + max(1, round(ticks / p))
        index = first + np.concatenate(([0], np.cumsum(steps)))
        self._stamp_ref = (int(stamps[-1]), int(index[-1]))
        return index


def nearest_rate(chip: str, rates: Iterable[float], odr_hz: float) -> float:
    """The rate of ``rates`` nearest ``odr_hz``.

    Raises
    ------
    ConfigurationError
        If it is more than :data:`ODR_RELATIVE_TOLERANCE` from ``odr_hz`` (the message lists
        the rates).
    """
    ordered = sorted(rates)
    odr = min(ordered, key=lambda r: abs(r - odr_hz))
    if not (odr_hz > 0 and abs(odr - odr_hz) <= ODR_RELATIVE_TOLERANCE * odr_hz):
        raise ConfigurationError(
            f"odr_hz={odr_hz!r} is not an {chip} output data rate gyrocal can stream over I²C; "
            "choose one of " + ", ".join(f"{r:g}" for r in ordered) + " Hz"
        )
    return odr
