"""Argument types shared by the ``gyrocal`` subcommands.

Each is an ``argparse`` ``type=`` callable that raises :class:`argparse.ArgumentTypeError` with a
message in the user's terms (the value as typed, what is allowed), so a bad flag ends in a usage
error (exit 2), never in a traceback from deep inside the kit.
"""

from __future__ import annotations

import argparse
import os

__all__ = ["i2c_address", "recording_dir", "seed"]

#: 7-bit I²C addresses a device may use (0x00–0x02 and 0x78–0x7F are reserved by the I²C-bus
#: specification, NXP UM10204 §3.1.12, Table 4).
I2C_ADDRESS_RANGE = (0x03, 0x77)


def seed(text: str) -> int:
    """A random seed: a whole number ≥ 0 (what numpy's generators accept)."""
    try:
        value = int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"seeds are whole numbers >= 0, got {text!r}"
        ) from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seeds are whole numbers >= 0, got {text}")
    return value


def i2c_address(text: str) -> int:
    """A 7-bit I²C address, in hex (``0x68``) or decimal (``104``); errors echo it as typed."""
    try:
        value = int(text.strip(), 0)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not an I2C address; give it in hex like 0x68 (MPU-9250) or 0x6B "
            "(LSM9DS1), as i2cdetect prints it"
        ) from None
    lo, hi = I2C_ADDRESS_RANGE
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(
            f"{text} is outside the 7-bit I2C addresses a device may use, {lo:#04x}..{hi:#04x}"
        )
    return value


def recording_dir(text: str) -> str:
    """A recording directory that exists (``text`` unchanged); its contents are checked when it
    is read (:func:`gyrocal.kit.recording.read_manifest`). Checked here so a mistyped path is a
    usage error before the command imports its modules."""
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(
            f"{text} is not a directory: give the recording directory")
    return text
