"""``gyrocal emulate --pty``: emulated Dynamixel servos behind a pseudo-terminal.

Any serial client (dynamixel-sdk, Dynamixel Wizard under Wine, ``gyrocal doctor --port``) can then
talk to three emulated X-series servos as to a real U2D2. The first line printed on standard
output is the device path (with ``--json``: one JSON object); the servos run until Ctrl-C,
SIGTERM, or ``--duration`` seconds.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

from gyrocal.kit import argtypes

HELP = "serve emulated Dynamixel servos on a pseudo-terminal (for any serial client)"
DESCRIPTION = __doc__


def _ids(text: str) -> list[int]:
    try:
        ids = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"IDs must be integers separated by commas, got {text!r}") from None
    if not ids or len(set(ids)) != len(ids) or any(not 0 <= i <= 252 for i in ids):
        raise argparse.ArgumentTypeError(f"IDs must be distinct integers 0..252, got {text!r}")
    return ids


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register the subcommand's options."""
    parser.add_argument("--pty", action="store_true",
                        help="serve on a pseudo-terminal and print its device path (required: "
                             "the only transport a separate process can reach)")
    parser.add_argument("--ids", type=_ids, default=[1, 2, 3],
                        help="servo IDs, comma-separated (default 1,2,3)")
    parser.add_argument("--model", default="XM430-W350",
                        help="servo model: XM430-W350 (default) or XL430-W250")
    parser.add_argument("--baud", type=int, default=1_000_000,
                        help="the servos' configured baud rate (default 1000000). A PTY moves "
                             "bytes at any speed, but the servos hear only a client whose port "
                             "is set to this rate, as on a real bus: a client at another rate "
                             "gets no reply at all (dynamixel-sdk: 'There is no status packet!'; "
                             "gyrocal doctor finds no servo), whatever it sends")
    parser.add_argument("--seed", type=argtypes.seed, default=0, help="random seed (default 0)")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds (default: until Ctrl-C or SIGTERM)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object {device, ids, model, baud} instead of the path")


def run(args: argparse.Namespace) -> int:
    """Serve until stopped; returns the exit code."""
    from gyrocal.drivers.clock import SystemClock
    from gyrocal.drivers.dynamixel.control_table import BAUD_RATES, model_by_name
    from gyrocal.drivers.emulated.dxl import PtyServoBridge, make_servo_bus
    from gyrocal.kit.errors import InputError

    if not args.pty:
        raise InputError("gyrocal emulate needs --pty (the in-process emulator is used by "
                         "'gyrocal calibrate --sim'; a separate process can only reach a PTY)")
    try:
        model = model_by_name(args.model)
    except ValueError as exc:
        raise InputError(str(exc)) from exc
    if args.baud not in BAUD_RATES.values():
        raise InputError(f"--baud must be one of {sorted(BAUD_RATES.values())}, got {args.baud}")
    if args.duration is not None and not args.duration > 0:
        raise InputError(f"--duration must be a positive number of seconds, got {args.duration}")
    clock = SystemClock()
    bus = make_servo_bus(clock, args.ids, model.name, args.seed, baudrate=args.baud)
    bridge = PtyServoBridge(bus)
    path = bridge.start()
    stop = threading.Event()
    old = {}

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        old[sig] = signal.signal(sig, on_signal)
    try:
        if args.json:
            print(json.dumps({"device": path, "ids": args.ids, "model": model.name,
                              "baud": args.baud}), flush=True)
        else:
            print(path, flush=True)
        print(f"gyrocal: {len(bus.servos)} emulated {model.name} servo(s), IDs "
              f"{','.join(map(str, args.ids))}, on {path}; stop with Ctrl-C", file=sys.stderr,
              flush=True)
        # Wake now and then: a serving thread that died must end the command at once, not
        # leave it serving nothing until Ctrl-C or the end of --duration.
        end = None if args.duration is None else clock.monotonic() + args.duration
        while not stop.is_set() and bridge.error is None:
            left = 0.5 if end is None else min(0.5, end - clock.monotonic())
            if left <= 0:
                break
            stop.wait(left)
        if bridge.error is not None:
            raise bridge.error
    finally:
        bridge.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return 0
