"""``gyrocal doctor``: check the jig and say in plain words what is wrong."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

HELP = "check the IMU and the servos and say what is wrong"
DESCRIPTION = (
    "Open the I2C bus and identify the IMU (WHO_AM_I), stream it briefly (rate, noise, "
    "temperature), ping the servos and read their model, firmware, voltage, temperature, "
    "limits and hardware errors, and tell in plain words what is wrong and what to do. With "
    "--sim it checks the emulated jig. Exit 0 if all is well, 4 if something needs fixing."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    from gyrocal.kit.commands.calibrate import add_common_jig_arguments

    add_common_jig_arguments(p)
    p.add_argument("--seconds", type=float, default=1.0, help="IMU test stream, s (default 1)")


class _Report:
    def __init__(self) -> None:
        self.problems = 0
        self.lines: list[str] = []

    def ok(self, text: str) -> None:
        self.lines.append(f"  ok    {text}")

    def warn(self, text: str, fix: str) -> None:
        self.lines.append(f"  warn  {text}\n        -> {fix}")

    def bad(self, text: str, fix: str | None = None) -> None:
        """A problem; ``fix`` says what to do (None when ``text`` already says it)."""
        self.problems += 1
        self.lines.append(f"  FAIL  {text}" + (f"\n        -> {fix}" if fix else ""))

    def section(self, title: str) -> None:
        self.lines.append(title)

    def flush(self) -> None:
        print("\n".join(self.lines))
        self.lines.clear()


def _scan_imus(rep: _Report, cfg: Any, args: argparse.Namespace, bus: Any) -> bool:
    """List the supported chips on the bus; False when the configured one is not there but
    another supported chip is (the fix is then said, and the configured check is skipped)."""
    from gyrocal.drivers.imu import open_bus
    from gyrocal.drivers.imu.detect import scan_bus
    from gyrocal.drivers.imu.errors import BusOpenError

    imu_cfg = cfg["imu"]
    try:
        handle = open_bus(bus) if isinstance(bus, (int, str)) else bus
    except BusOpenError:
        return True  # the configured check says what is wrong with the bus
    try:
        found = scan_bus(handle)
    finally:
        if handle is not bus:
            handle.close()
    rep.section("IMUs on the bus (WHO_AM_I at every address a supported chip can have)")
    if not found:
        rep.bad("no device answers at any supported IMU address",
                "check the wiring (SDA, SCL, GND, 3.3 V) and list the bus with `i2cdetect -y N`")
        return True
    for chip in found:
        what = chip.title if chip.model else chip.title.removeprefix("an ").removeprefix("a ")
        who = f" (WHO_AM_I 0x{chip.who_am_i:02X})" if chip.who_am_i is not None else ""
        rep.ok(f"0x{chip.address:02X}: {what}{who}"
               + (f", model '{chip.model}'" if chip.model else ""))
    supported = [c for c in found if c.model]
    model, address = str(imu_cfg["model"]).replace("-", "").lower(), imu_cfg["address"]
    if any(c.model == model and address in (0, c.address) for c in supported) or not supported:
        return True
    other = supported[0]
    at = f"at 0x{address:02X}" if address else "at its addresses"
    rep.bad(f"the configured {imu_cfg['model']} {at} "
            f"is not on the bus, but an {other.title} is at 0x{other.address:02X}",
            f"set imu.model = \"{other.model}\" and imu.address = 0x{other.address:02X} in "
            f"the config (or --imu-model {other.model} --imu-address 0x{other.address:02X})")
    return False


def _check_imu(rep: _Report, cfg: Any, args: argparse.Namespace, clock: Any, bus: Any) -> None:
    import numpy as np

    from gyrocal.calib.observations import diff_noise
    from gyrocal.drivers.errors import DriverError
    from gyrocal.drivers.imu import READERS, open_imu
    from gyrocal.kit.jig import note_rounded_odr, resolve_sensor

    imu_cfg = cfg["imu"]
    where = "the emulated bus" if args.sim else f"/dev/i2c-{imu_cfg['bus']}"
    try:
        chip = resolve_sensor(imu_cfg, bus)
    except DriverError as exc:  # the chip answers at several of its addresses
        rep.section(f"IMU ({imu_cfg['model']} on {where})")
        rep.bad(str(exc))
        return
    rep.section(f"IMU ({imu_cfg['model']} at 0x{chip['address']:02X} on {where})")
    try:
        reader = open_imu(imu_cfg["model"], bus, chip["address"], clock=clock,
                          range_dps=imu_cfg["range_dps"], odr_hz=chip["odr_hz"])
    except DriverError as exc:  # the drivers' messages say what to do
        rep.bad(str(exc))
        return
    try:
        info = reader.info
        note_rounded_odr(imu_cfg["odr_hz"], info)
        rep.ok(f"found {info.model} (WHO_AM_I 0x{info.who_am_i:02X}), ±{info.full_scale_dps:g} "
               f"°/s, {info.odr_hz:g} Hz, low-pass {info.lowpass_hz:g} Hz")
        if getattr(reader, "notice", None):
            rep.warn(str(reader.notice), "fine for gyro calibration")
        reader.start()
        end = clock.monotonic() + args.seconds
        batches = []
        while clock.monotonic() < end:
            clock.sleep(0.01)
            batches.append(reader.read())
        rate = np.concatenate([b.rate for b in batches])
        temp = np.concatenate([b.temperature_c for b in batches])
        gaps = sum(len(b.gaps) for b in batches)
        n = rate.shape[0]
        expect = info.odr_hz * args.seconds
        if n < 0.8 * expect:
            rep.bad(f"only {n} samples in {args.seconds:g} s (expected about {expect:.0f})",
                    "check the I2C speed (400 kHz: dtparam=i2c_arm_baudrate=400000)")
        else:
            measured = reader.measured_odr_hz
            rep.ok(f"{n} samples in {args.seconds:g} s"
                   + (f", chip clock {measured:.2f} Hz" if measured else ""))
        if gaps:
            rep.bad(f"{gaps} FIFO gap(s) while streaming", "a faster I2C bus, or a lower odr_hz")
        sigma = diff_noise(rate)
        mean = rate.mean(axis=0)
        rep.ok(f"at rest: mean [{mean[0]:+.4f} {mean[1]:+.4f} {mean[2]:+.4f}] rad/s, noise "
               f"[{sigma[0]:.4f} {sigma[1]:.4f} {sigma[2]:.4f}] rad/s per sample, "
               f"{np.mean(temp):.1f} °C")
        # 0.3 rad/s, or the chip's datasheet zero-rate offset where it allows more (LSM9DS1:
        # ±30 °/s, ChipFamily.gyro_errors)
        limit = max(0.3, READERS[imu_cfg["model"]].family.gyro_errors.zero_rate_rad_s)
        if np.any(np.abs(mean) > limit):
            rep.warn(f"a large rate at rest (> {limit:.2g} rad/s)",
                     "keep the jig still while doctor runs; a bias this large is beyond what "
                     "the chip's datasheet allows")
        if np.any(sigma < 1e-6):
            rep.bad("an axis does not change at all", "the chip may be broken (a stuck axis)")
    except DriverError as exc:
        rep.bad(str(exc))
    finally:
        reader.close()


def latency_timer_ms(port: str, sysfs: str = "/sys/bus/usb-serial/devices") -> int | None:
    """The FTDI latency timer of a USB serial port (the U2D2), ms; None if it has none.

    Linux exposes it as ``<sysfs>/ttyUSBn/latency_timer``; ``port`` may be a symlink such as
    ``/dev/serial/by-id/...``.
    """
    import os

    name = os.path.basename(os.path.realpath(port))
    try:
        with open(os.path.join(sysfs, name, "latency_timer"), encoding="ascii") as fh:
            return int(fh.read().strip())
    except (OSError, ValueError):
        return None


def _check_servos(rep: _Report, cfg: Any, args: argparse.Namespace, clock: Any, port: Any,
                  baud: int) -> None:
    from gyrocal.drivers.dynamixel import Gimbal
    from gyrocal.drivers.errors import DriverError

    g = cfg["gimbal"]
    rep.section(f"servos {g['ids']} on {'the emulated bus' if args.sim else g['port']} "
                f"at {baud} baud")
    if isinstance(port, str):
        latency = latency_timer_ms(port)
        if latency is not None and latency > 1:
            rep.warn(f"the USB serial latency timer of {port} is {latency} ms: every servo read "
                     "waits that long",
                     "set it to 1 ms with the udev rule in hardware_docs/setup.md (FTDI "
                     "0403:6014), then unplug and replug the U2D2")
        elif latency == 1:
            rep.ok(f"USB serial latency timer of {port}: 1 ms")
    if baud < 1_000_000:
        rep.warn(f"{baud} baud limits the position sampling rate (about 55-80 sync reads/s at "
                 "57600 for three servos)",
                 "set the servos to 1 Mbps (Dynamixel Wizard) and gimbal.baud = 1000000")
    gimbal = Gimbal(port, g["ids"], baudrate=baud, clock=clock, handle_signals=True,
                    retries=g["retries"])
    try:
        with gimbal:
            for note in gimbal.notices:
                rep.warn(note, "fine if its control table matches the X-430 series")
            status = gimbal.read_status()
            for sid in g["ids"]:
                info = gimbal.infos[sid]
                st = status[sid]
                lo, hi = info.voltage_limits_v
                rep.ok(f"servo {sid}: {info.model_name}, firmware {info.firmware}, "
                       f"{st.voltage_v:.1f} V, {st.temperature_c:.0f} °C, top speed "
                       f"{math.degrees(info.max_speed):.0f}°/s "
                       f"(Velocity Limit {math.degrees(info.velocity_limit):.0f}°/s)")
                if not lo <= st.voltage_v <= hi:
                    rep.bad(f"servo {sid}: supply {st.voltage_v:.1f} V outside {lo:g}-{hi:g} V",
                            "check the power supply and its cable")
                if st.temperature_c > info.temperature_limit_c - 10:
                    rep.bad(f"servo {sid} is hot ({st.temperature_c:.0f} °C)",
                            "let it cool down before calibrating")
                if st.hardware_error:
                    rep.bad(f"servo {sid} reports {', '.join(st.hardware_error_names)}",
                            "fix the cause, then power-cycle or reboot the servo")
                if info.return_delay_s > 1e-4 and not args.sim:  # not the emulator's own
                    rep.warn(f"servo {sid}: Return Delay Time {info.return_delay_s * 1e6:.0f} µs",
                             "0 µs (Dynamixel Wizard) gives the fastest position sampling")
    except DriverError as exc:
        rep.bad(str(exc))


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.kit.errors import HardwareError
    from gyrocal.kit.jig import jig_endpoints, load_cli_config

    cfg = load_cli_config(args)
    sim, clock, port, baud, bus = jig_endpoints(cfg, args)
    if sim is not None:
        from gyrocal.kit.sim import apply_fault

        for spec in args.sim_fault:
            apply_fault(sim, spec, clock.monotonic())
    rep = _Report()
    print(f"gyrocal doctor ({'emulated jig' if args.sim else 'hardware'}; config: {cfg.source})")
    if _scan_imus(rep, cfg, args, bus):
        _check_imu(rep, cfg, args, clock, bus)
    rep.flush()
    _check_servos(rep, cfg, args, clock, port, baud)
    rep.flush()
    if rep.problems:
        print(f"\n{rep.problems} problem(s) found", file=sys.stderr)
        raise HardwareError(f"doctor found {rep.problems} problem(s); see above")
    if args.sim:
        print("\nall checks passed on the emulated jig: `gyrocal calibrate --sim` calibrates it")
    else:
        print("\nall checks passed: run `gyrocal calibrate`")
    return 0
