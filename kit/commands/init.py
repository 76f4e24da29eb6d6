"""``gyrocal init``: write a commented ``gyrocal.toml`` with every key at its default."""

from __future__ import annotations

import argparse

HELP = "write a commented gyrocal.toml to edit"
DESCRIPTION = (
    "Write a configuration file with every key, its default and what it means: the serial port "
    "and servo IDs, which sensor axis each servo turns about, the IMU model, bus, address, range "
    "and rate, and the protocol. Refuses to overwrite without --force."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Register the arguments."""
    p.add_argument("path", nargs="?", default="gyrocal.toml", help="default: gyrocal.toml")
    p.add_argument("--force", action="store_true", help="replace an existing file")
    p.add_argument("--imu-model", default=None, metavar="MODEL",
                   help="write [imu] for this chip (mpu9250, lsm9ds1, icm20948, icm42688p, "
                        "lsm6dsox, ...): its default address and the output data rate it has "
                        "nearest the default")


def run(args: argparse.Namespace) -> int:
    """Run the command."""
    from gyrocal.drivers.imu import MODELS
    from gyrocal.kit.config import template
    from gyrocal.kit.errors import InputError
    from gyrocal.kit.fileio import atomic_write_text

    # checked here, not as argparse choices: --help must not import the drivers
    # (tests/kit/test_cli_imports.py)
    if args.imu_model is not None and args.imu_model not in MODELS:
        raise InputError(f"--imu-model {args.imu_model!r} is not a chip gyrocal reads; give one "
                         f"of {', '.join(MODELS)}")

    atomic_write_text(args.path, template(args.imu_model), force=args.force)
    print(f"wrote {args.path}; edit it, then run `gyrocal doctor --config {args.path}`")
    return 0
