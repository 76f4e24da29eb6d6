"""The emulated jig: servos, gimbal physics and IMU chip on one clock, for ``--sim``.

The same code path runs as on hardware: the real dynamixel-sdk encodes and decodes every servo
packet (through the in-process transport), and the real IMU reader talks to a register-level
emulated chip on an emulated SMBus. Only the bus objects and the clock differ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calib.simulate import NORMAL, draw_sensors
from drivers.clock import Clock, SystemClock, VirtualClock
from drivers.emulated.dxl import make_emulated_gimbal
from drivers.emulated.imu_chips import SensorTruth, make_emulated_imu
from kit.config import Config
from kit.errors import InputError

__all__ = ["SimJig", "build_sim", "sim_truth"]

#: Servo model of the emulated jig.
SIM_SERVO_MODEL = "XM430-W350"
#: Bus speed of the emulated jig (a jig set up for gyrocal runs at 1 Mbps).
SIM_BAUD = 1_000_000


@dataclass
class SimJig:
    """Everything ``--sim`` assembles.

    Attributes
    ----------
    clock : Clock
        Virtual (default) or the system clock (``--realtime``).
    port : PortHandler
        The in-process servo transport, for :class:`drivers.dynamixel.Gimbal`.
    servo_bus : ServoBus
        The emulated servos (``servo_bus.servo(id)`` has the fault knobs).
    jig : GimbalJig
        Gimbal physics: the IMU's motion source; ``jig.home_axes`` is the truth of each axis.
    imu_bus : EmulatedSMBus
        The emulated I²C bus with the chip on it.
    imu_address : int
    truth : SensorTruth
        The sensor's true errors.
    """

    clock: Clock
    port: Any
    servo_bus: Any
    jig: Any
    imu_bus: Any
    imu_address: int
    truth: SensorTruth

    @property
    def chip(self) -> Any:
        """The emulated IMU chip (fault knobs)."""
        return self.imu_bus.device(self.imu_address)

    def servo_state(self) -> dict[str, Any]:
        """Each emulated servo's torque and goal velocity as the emulator holds them."""
        out = {}
        for s in self.servo_bus.servos:
            out[str(s.dxl_id)] = {
                "torque_enable": int(s.register("Torque Enable")),
                "goal_velocity": int(s.register("Goal Velocity")),
                "hardware_error": int(s.register("Hardware Error Status")),
            }
        return out


def sim_truth(
    seed: int, scale: list[float] | None = None, bias: list[float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """True scale and bias: drawn from the paper's normal conditions by ``seed`` unless given."""
    k, b = draw_sensors(np.random.default_rng(seed), 1, NORMAL)
    k, b = k[0], b[0]
    if scale is not None:
        k = np.asarray(scale, dtype=float)
        if k.shape != (3,) or not np.all(k > 0):
            raise InputError(f"--sim-scale needs three positive numbers, got {scale}")
    if bias is not None:
        b = np.asarray(bias, dtype=float)
        if b.shape != (3,) or not np.all(np.isfinite(b)):
            raise InputError(f"--sim-bias needs three numbers (rad/s), got {bias}")
    return k, b


def build_sim(
    cfg: Config,
    *,
    seed: int = 0,
    scale: list[float] | None = None,
    bias: list[float] | None = None,
    realtime: bool = False,
    noise_density_rad_s_sqrt_hz: float | None = None,
    mount_deg: float = 3.0,
) -> SimJig:
    """Assemble the emulated jig described by ``cfg`` (IDs, axes, IMU model and address).

    Parameters
    ----------
    cfg : Config
    seed : int
        Seeds the sensor's true errors (paper's normal conditions), the mount misalignment, the
        servo ripple and every noise source.
    scale, bias : list of 3 float, optional
        Fix the sensor's true scale and bias instead of drawing them.
    realtime : bool
        Run on the system clock (a demonstration at the jig's real pace).
    noise_density_rad_s_sqrt_hz : float, optional
        Gyro white-noise density; the chip's typical figure when omitted.
    mount_deg : float
        Misalignment of the sensor's mount, degrees (random axis).
    """
    clock: Clock = SystemClock() if realtime else VirtualClock()
    k, b = sim_truth(seed, scale, bias)
    g = cfg["gimbal"]
    port, servo_bus, jig = make_emulated_gimbal(
        clock, g["ids"], SIM_SERVO_MODEL, seed, baudrate=SIM_BAUD, axes=g["axes"],
        mount=mount_deg,
    )
    truth_kw: dict[str, Any] = {"scale": tuple(k), "bias": tuple(b)}
    if noise_density_rad_s_sqrt_hz is not None:
        truth_kw["noise_density_rad_s_sqrt_hz"] = noise_density_rad_s_sqrt_hz
    truth = SensorTruth(**truth_kw)
    imu_cfg = cfg["imu"]
    imu_bus, address = make_emulated_imu(
        imu_cfg["model"], clock, jig, truth, address=imu_cfg["address"], seed=seed,
    )
    return SimJig(clock, port, servo_bus, jig, imu_bus, address, truth)


def axis_truth_deg(sim: SimJig) -> dict[str, float]:
    """Each servo's true misalignment (degrees off the nearest sensor axis), for reports."""
    out = {}
    for sid, u in sim.jig.home_axes.items():
        out[str(sid)] = math.degrees(math.acos(min(1.0, float(np.max(np.abs(u))))))
    return out
