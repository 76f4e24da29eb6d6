"""Talking to hardware: IMU readers over smbus2, the Dynamixel gimbal over dynamixel-sdk, and
emulated hardware (``gyrocal.drivers.emulated``) for tests and dry runs.

``drivers`` never imports ``calib``; ``kit`` joins the two.
"""
