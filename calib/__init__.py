"""Pure numerics for gyroscope calibration: no files, no hardware, no clocks, no printing.

Functions take arrays and return frozen dataclasses. ``calib`` never imports ``drivers``.
"""
