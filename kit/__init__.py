"""The gyrocal application: the ``gyrocal`` command line, configuration, the protocol runner,
recording files and reports. ``kit`` joins ``drivers`` (hardware) and ``calib`` (numerics).
"""

__version__ = "0.1.0"
