"""Emulated hardware: register-level IMU chips on an emulated SMBus, byte-level Protocol 2.0 servos,
and the jig's physics. Shipped with the library so users can dry-run without hardware.
"""
