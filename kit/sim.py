"""The emulated jig: servos, gimbal physics and IMU chip on one clock, for ``--sim``.

The same code path runs as on hardware: the real dynamixel-sdk encodes and decodes every servo
packet (through the in-process transport), and the real IMU reader talks to a register-level
emulated chip on an emulated SMBus. Only the bus objects and the clock differ.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gyrocal.calib.simulate import EXTREME, NORMAL, SensorPreset, draw_sensors
from gyrocal.drivers.clock import Clock, SystemClock, VirtualClock
from gyrocal.drivers.dynamixel.control_table import XM430_W350
from gyrocal.drivers.emulated.accel import ACCEL_DATASHEET, draw_accel_truth
from gyrocal.drivers.emulated.dxl import GimbalJig, make_emulated_gimbal
from gyrocal.drivers.emulated.imu_chips import SensorRealism, SensorTruth, make_emulated_imu
from gyrocal.drivers.imu import READERS
from gyrocal.drivers.imu.chips import MPU9250
from gyrocal.kit.config import Config
from gyrocal.kit.errors import InputError

__all__ = ["DATASHEET_CROSS_AXIS", "HAND_STOP_DEG", "HAND_WOBBLE_DEG", "REALISM_EFFECTS",
           "SIM_CROSS_AXIS", "SIM_SENSOR", "SIM_SENSORS", "SimJig", "build_hand_sim",
           "build_sim", "build_sim_plate", "plate_seed",
           "realism_sizes", "sensor_preset", "sim_cross_axis", "sim_misalignment",
           "sim_realism", "sim_thermal", "sim_truth"]

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
        The in-process servo transport, for :class:`gyrocal.drivers.dynamixel.Gimbal`.
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
    realism: frozenset[str] = field(default_factory=frozenset)
    #: Every sensor's view of a plate of several (:func:`build_sim_plate`), this one first;
    #: empty for a single sensor.
    plate: list[Any] = field(default_factory=list, repr=False)
    #: Re-seats (0-based prompts) at which the emulated user seats the single-servo jig's cube
    #: wrong (``--sim-fault seat:N``; :class:`~gyrocal.drivers.emulated.seater.CubeSeater`).
    wrong_seats: set[int] = field(default_factory=set, repr=False)

    def truth_manifest(self) -> dict[str, Any]:
        """The manifest's ``truth``: the sensor's errors, the axes, and one line per realism
        effect (its size, or ``"off"``)."""
        r = self.truth.realism
        on = self.realism
        lines: dict[str, Any] = {
            "coloured-noise": {"bias_instability_rad_s": r.bias_instability_rad_s,
                               "rate_random_walk_rad_s_sqrt_s": r.rate_random_walk_rad_s_sqrt_s},
            "dlpf": {"cutoff_hz": self.chip.cutoff_hz(), "order": self.chip.filter_order(),
                     "delay_s": getattr(self.chip, "delay_s", lambda: None)()
                     } if r.dlpf_delay else "off",
            "g-sensitivity": {
                "matrix_rad_s_per_g": [list(x) for x in r.g_sensitivity_rad_s_per_g],
                # what it adds to the bias in the home pose, where a calibration's rests are
                "home_bias_shift_rad_s": (np.asarray(r.g_sensitivity_rad_s_per_g)
                                          @ self.jig.home_gravity()).tolist()},
            "gravity": {"lever_arm_m": self.jig.lever_arm_m.tolist()},
            "accel-errors": self.truth.manifest().get("accelerometer", "off"),
            "wobble": {"amplitude_rad": self.jig.wobble_rad,
                       "axes": self.jig.wobble_axes.tolist()},
            "clock": {"clock_ppm": self.truth.clock_ppm},
            "encoder-latency": {"model_timing": bool(self.port.model_timing)},
        }
        realism = {k: (v if k in on else "off") for k, v in lines.items()}
        return {**self.truth.manifest(), "realism": realism}

    def turn_axes(
        self, ids: list[int], turn_times: dict[int, list[float]], t0: float
    ) -> dict[str, list[float]]:
        """Each servo's true axis in the sensor frame at the middle of its turns (the mean over
        its turns), ``turn_times`` on the recording clock that starts at ``t0`` on the jig's."""
        out = {}
        for j, sid in enumerate(ids):
            times = turn_times.get(sid)
            if not times:
                out[str(sid)] = self.jig.home_axes[sid].tolist()
                continue
            axes = self.jig.joint_axes_sensor(np.asarray(times) + t0)[:, j, :]
            u = axes.mean(axis=0)
            out[str(sid)] = (u / np.linalg.norm(u)).tolist()
        return out

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


#: The MPU-9250 datasheet's cross-axis sensitivity, ±2 % (PS-MPU-9250A-01 §3.1, Gyroscope
#: Specifications): the default of ``--sim-cross-axis`` for the default chip. Each chip's own
#: figure is its ``ChipFamily.gyro_errors.cross_axis``; ``--sim-cross-axis 0`` gives a sensor
#: without cross-axis terms, as the paper's model has none.
DATASHEET_CROSS_AXIS = MPU9250.gyro_errors.cross_axis
SIM_CROSS_AXIS = DATASHEET_CROSS_AXIS

#: ``--sim-sensor``: where the emulated sensor's true scale factors and biases are drawn from.
SIM_SENSORS: dict[str, str] = {
    "datasheet": "within the chip's datasheet tolerances: sensitivity (scale) tolerance and "
                 "initial zero-rate offset (ChipFamily.gyro_errors; MPU-9250: ±3 %, ±5 °/s)",
    "paper": "the paper's normal conditions (its Section III simulations): scale U(0.8, 1.2), "
             "bias U(-0.1, 0.1) rad/s, beyond any datasheet of today's chips",
    "paper-extreme": "the paper's extreme conditions: scale U(1.2, 2.0), |bias| U(0.1, 0.2) "
                     "rad/s with a random sign",
}
#: The default ``--sim-sensor``: a sensor as its datasheet allows.
SIM_SENSOR = "datasheet"


def sim_misalignment(seed: int, cross_axis: float = SIM_CROSS_AXIS) -> np.ndarray:
    """The emulated sensor's cross-axis matrix (``SensorTruth.misalignment``): the identity plus
    off-diagonal terms drawn by ``seed`` and scaled so that the largest is ``±cross_axis``
    (0 gives the identity, as in the paper's model).

    Raises
    ------
    InputError
        If ``cross_axis`` is negative, not finite or 0.2 or more (beyond any datasheet).
    """
    if not (np.isfinite(cross_axis) and 0.0 <= cross_axis < 0.2):
        raise InputError(
            f"--sim-cross-axis must be a fraction in [0, 0.2), got {cross_axis!r} "
            "(0.02 is the MPU-9250 datasheet's ±2 %)")
    off = np.random.default_rng([int(seed), 0xC055]).uniform(-1.0, 1.0, (3, 3))
    off *= 1.0 - np.eye(3)
    return np.eye(3) + cross_axis * off / np.max(np.abs(off))


#: The realism effects of the emulated sensor and jig, all on in ``--sim`` unless turned off
#: (``--sim-realism off``, ``--sim-without EFFECT``): name → what it is and its size's source.
#: ⚠ marks a size assumed for lack of a datasheet figure.
REALISM_EFFECTS: dict[str, str] = {
    "coloured-noise": "bias instability (flicker: Gauss–Markov sum) and rate random walk, the "
                      "chip's GyroErrors figures ⚠ (assumed: no datasheet gives them)",
    "dlpf": "the chip's digital low-passes at the configured settings, gyro and "
            "accelerometer, the white noise entering ahead of each (MPU-9250: 92 Hz with the "
            "CONFIG table's 3.9 ms at 200 Hz; its accelerometer 218.1 Hz at 1 kHz)",
    "g-sensitivity": "rate error per g of specific force, each term drawn by seed within "
                     "the chip's GyroErrors figure (MPU-9250: 0.1 °/s/g)",
    "gravity": "the accelerometer sees gravity in the true orientation and the lever-arm "
               "accelerations of a sensor SIM_LEVER_ARM_M off the axes ⚠ (jig geometry)",
    "accel-errors": "the accelerometer's scale, cross-axis, zero-g bias and noise, each term "
                    "drawn by seed within the datasheet's figure (ACCEL_DATASHEET)",
    "wobble": "each turning link nods SIM_WOBBLE_DEG once per revolution ⚠ (assumed)",
    "clock": "chip clock off by up to SIM_CLOCK_PPM, drawn by seed ⚠ (assumed)",
    "encoder-latency": "Present Position sampled at the servo's reply (after the instruction, "
                       "Return Delay Time and earlier replies at the bus baud), not at the "
                       "host's timestamp",
}
#: The sensor's offset from the meeting point of the gimbal's axes, m (sensor frame) ⚠.
SIM_LEVER_ARM_M = (0.02, -0.015, 0.03)
#: Once-per-revolution tilt of each turning link, degrees ⚠: the servo table's assumed figure,
#: the one a calibration's σ allow for (``ServoModel.wobble_deg``).
SIM_WOBBLE_DEG = XM430_W350.wobble_deg
#: Largest chip clock error drawn, ppm ⚠.
SIM_CLOCK_PPM = 300.0


def realism_sizes(family: str = "mpu9250") -> dict[str, str]:
    """Each realism effect's size in ``--sim``, in words with its figures (⚠: assumed)."""
    ge = _family(family).gyro_errors
    acc = ACCEL_DATASHEET.get(family, ACCEL_DATASHEET["mpu9250"])
    arm = math.hypot(*SIM_LEVER_ARM_M) * 1000
    return {
        "coloured-noise": f"B {ge.bias_instability_deg_h:g} °/h, "
                          f"K {ge.rate_random_walk_rad_s_sqrt_s:g} rad/s/√s ⚠",
        "dlpf": ("92 Hz, 3.9 ms at 200 Hz (CONFIG table)" if family == "mpu9250"
                 else "the configured setting's bandwidth"),
        "g-sensitivity": f"±{ge.g_sensitivity_dps_per_g:g} °/s/g per term ({ge.noise_source})",
        "gravity": f"1 g in the true pose, lever arm {arm:.0f} mm ⚠",
        "accel-errors": "scale ±{:g} %, cross-axis ±{:g} %, zero-g ±{:g} mg, {:g} µg/√Hz ({})"
                        .format(100 * acc["scale_tolerance"], 100 * acc["cross_axis"],
                                1000 * max(acc["zero_g_g"]), 1e6 * acc["noise_g_sqrt_hz"],
                                acc["source"]),
        "wobble": f"{SIM_WOBBLE_DEG:g}° once per revolution ⚠",
        "clock": f"±{SIM_CLOCK_PPM:g} ppm ⚠",
        "encoder-latency": f"instruction + 500 µs RDT + packets at {SIM_BAUD / 1e6:g} Mbps",
    }


def sim_realism(family: str, seed: int, effects: Collection[str]) -> tuple[SensorRealism, float]:
    """The emulated chip's realism and clock error (ppm) for the ``effects`` that are on,
    drawn by ``seed`` (the g-sensitivity terms and the clock error).

    Raises
    ------
    InputError
        If an effect is not one of :data:`REALISM_EFFECTS`.
    """
    unknown = set(effects) - set(REALISM_EFFECTS)
    if unknown:
        raise InputError(f"unknown realism effect {sorted(unknown)[0]!r}; choose from "
                         + ", ".join(REALISM_EFFECTS))
    ge = _family(family).gyro_errors
    rng = np.random.default_rng([int(seed), 0x4EA1])
    g_sens = rng.uniform(-1.0, 1.0, (3, 3)) * math.radians(ge.g_sensitivity_dps_per_g)
    ppm = float(rng.uniform(-1.0, 1.0)) * SIM_CLOCK_PPM
    on = set(effects)
    realism = SensorRealism(
        bias_instability_rad_s=(ge.bias_instability_rad_s if "coloured-noise" in on else 0.0),
        rate_random_walk_rad_s_sqrt_s=(ge.rate_random_walk_rad_s_sqrt_s
                                       if "coloured-noise" in on else 0.0),
        dlpf_delay="dlpf" in on,
        g_sensitivity_rad_s_per_g=g_sens if "g-sensitivity" in on else np.zeros((3, 3)),
        specific_force="gravity" in on,
    )
    return realism, (ppm if "clock" in on else 0.0)


def sensor_preset(sensor: str = SIM_SENSOR, family: str = "mpu9250") -> SensorPreset:
    """The distribution ``--sim-sensor SENSOR`` draws a ``family`` chip's true scale factors and
    biases from (:data:`SIM_SENSORS`).

    ``datasheet`` is the chip's sensitivity tolerance and initial zero-rate offset
    (:class:`~gyrocal.drivers.imu.chips.GyroErrors`); ``paper`` and ``paper-extreme`` are the
    paper's normal and extreme conditions (Section III), whatever the chip.

    Raises
    ------
    InputError
        If ``sensor`` is not one of :data:`SIM_SENSORS`.
    """
    if sensor == "paper":
        return NORMAL
    if sensor == "paper-extreme":
        return EXTREME
    if sensor != "datasheet":
        raise InputError(f"--sim-sensor {sensor!r}: choose one of " + ", ".join(SIM_SENSORS))
    errors = _family(family).gyro_errors
    return SensorPreset((1.0 - errors.scale_tolerance, 1.0 + errors.scale_tolerance),
                        (0.0, errors.zero_rate_rad_s))


def sim_cross_axis(family: str = "mpu9250") -> float:
    """The default ``--sim-cross-axis`` of a ``family`` chip: its datasheet's cross-axis
    sensitivity (``ChipFamily.gyro_errors.cross_axis``)."""
    return _family(family).gyro_errors.cross_axis


def _family(name: str) -> Any:
    """The chip family named ``name`` (a family or a model name)."""
    for reader in READERS.values():
        if reader.family.name == name:
            return reader.family
    return READERS[name].family


def sim_truth(
    seed: int, scale: list[float] | None = None, bias: list[float] | None = None, *,
    sensor: str = SIM_SENSOR, family: str = "mpu9250",
) -> tuple[np.ndarray, np.ndarray]:
    """True scale and bias: drawn by ``seed`` from :func:`sensor_preset` ``(sensor, family)``
    unless given.

    The draw is the same stream of uniforms for every ``sensor``, so a seed's sensor keeps the
    sign and the place within its range of each term: a ``datasheet`` scale is
    ``1 + (k - 1) · tol / 0.2`` of the ``paper`` one ``k``.
    """
    k, b = draw_sensors(np.random.default_rng(seed), 1, sensor_preset(sensor, family))
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
    noise_seed: int | None = None,
    cross_axis: float | None = None,
    realism: Collection[str] | None = None,
    temperature: str | None = None,
    self_heating: str | None = None,
    sensor: str = SIM_SENSOR,
) -> SimJig:
    """Assemble the emulated jig described by ``cfg`` (IDs, axes, IMU model and address).

    Parameters
    ----------
    cfg : Config
    seed : int
        Seeds the sensor's true errors (drawn as ``sensor`` says) and the jig's geometry (the
        mount misalignment and the servo axes' tilts): which sensor on which jig.
    noise_seed : int, optional
        Seeds what differs from run to run on the same jig: the gyro noise and the servos'
        ripple. Defaults to ``seed``; a different value repeats a run with fresh noise.
    scale, bias : list of 3 float, optional
        Fix the sensor's true scale and bias instead of drawing them.
    realtime : bool
        Run on the system clock (a demonstration at the jig's real pace).
    noise_density_rad_s_sqrt_hz : float, optional
        Gyro white-noise density; the chip's typical figure when omitted.
    mount_deg : float
        Misalignment of the sensor's mount, degrees (random axis).
    cross_axis : float, optional
        Largest off-diagonal term of the sensor's cross-axis matrix, drawn by ``seed``
        (:func:`sim_misalignment`); the chip's datasheet figure when omitted
        (:func:`sim_cross_axis`), 0 for none (the paper's model has none).
    realism : collection of str, optional
        The :data:`REALISM_EFFECTS` that are on; all of them when omitted, none with ``()``.
    temperature, self_heating : str, optional
        ``--sim-temperature`` and ``--sim-self-heating`` (:func:`sim_thermal`): either turns on
        the die's warm-up and temperature coefficients drawn by ``seed``; without both the die
        stays at 25 °C and the sensor has no temperature terms.
    sensor : str
        ``--sim-sensor`` (:data:`SIM_SENSORS`): the true scale factors and biases within the
        chip's datasheet tolerances (default), or the paper's normal or extreme conditions.
    """
    clock: Clock = SystemClock() if realtime else VirtualClock()
    g = cfg["gimbal"]
    run_seed = seed if noise_seed is None else noise_seed
    effects = frozenset(REALISM_EFFECTS if realism is None else realism)
    port, servo_bus, _ = make_emulated_gimbal(
        clock, g["ids"], SIM_SERVO_MODEL, run_seed, baudrate=SIM_BAUD, axes=g["axes"],
        mount=mount_deg, model_timing="encoder-latency" in effects,
    )
    jig = GimbalJig(servo_bus.servos, axes=g["axes"], mount=mount_deg, seed=seed,
                    wobble_deg=SIM_WOBBLE_DEG if "wobble" in effects else 0.0,
                    lever_arm_m=SIM_LEVER_ARM_M if "gravity" in effects else (0.0, 0.0, 0.0))
    plate = SimJig(clock, port, servo_bus, jig, None, 0, SensorTruth(), effects)
    family = READERS[cfg["imu"]["model"]].family.name
    truth = sim_truth(seed, scale, bias, sensor=sensor, family=family)
    return _add_sensor(plate, cfg["imu"], seed, run_seed, truth,
                       cross_axis=cross_axis, noise_density=noise_density_rad_s_sqrt_hz,
                       temperature=temperature, self_heating=self_heating)


def _add_sensor(plate: SimJig, imu_cfg: dict[str, Any], seed: int, run_seed: int,
                scale_bias: tuple[np.ndarray, np.ndarray], *, cross_axis: float | None,
                noise_density: float | None, temperature: str | None,
                self_heating: str | None, bus: Any = None) -> SimJig:
    """One emulated sensor on the plate's jig: its truth drawn by ``seed`` (scale, bias from
    ``scale_bias``; its cross-axis terms up to ``cross_axis``, the chip's datasheet figure when
    None), its chip on ``bus`` (a new emulated bus when None); the returned
    :class:`SimJig` shares the plate's clock, servos and joints."""
    k, b = scale_bias
    family = READERS[imu_cfg["model"]].family
    sensor_realism, ppm = sim_realism(family.name, seed, plate.realism)
    truth_kw: dict[str, Any] = {"scale": tuple(k), "bias": tuple(b),
                                "misalignment": sim_misalignment(
                                    seed, sim_cross_axis(family.name) if cross_axis is None
                                    else cross_axis),
                                "realism": sensor_realism, "clock_ppm": ppm}
    if "accel-errors" in plate.realism:
        truth_kw["accelerometer"] = draw_accel_truth(family.name, seed)
    truth_kw["noise_density_rad_s_sqrt_hz"] = (family.gyro_errors.noise_density_rad_s_sqrt_hz
                                               if noise_density is None else noise_density)
    if temperature is not None or self_heating is not None:
        truth_kw.update(sim_thermal(seed, imu_cfg["model"], temperature, self_heating,
                                    plate.clock.monotonic()))
    truth = SensorTruth(**truth_kw)
    # The chip sits where a real one of its model can (the configured address if the model
    # allows it, else its default), so a config that names the wrong address fails as it would
    # on hardware.
    possible = family.addresses  # hardware reference §1.1, §2.1
    imu_bus, address = make_emulated_imu(
        imu_cfg["model"], plate.clock, plate.jig, truth, seed=run_seed, bus=bus,
        address=imu_cfg["address"] if imu_cfg["address"] in possible else None,
        output_filter="dlpf" in plate.realism,
    )
    return replace(plate, imu_bus=imu_bus, imu_address=address, truth=truth)


#: Where the k-th sensor of a plate sits from the first, m (sensor frame): a row of boards
#: 25 mm apart ⚠ (jig geometry; it sets each one's lever arm).
SIM_PLATE_PITCH_M = (0.025, 0.0, 0.0)


def plate_seed(seed: int, k: int) -> int:
    """The seed of the ``k``-th sensor on an emulated plate: ``seed`` itself for the first (so
    a one-sensor plate is the one-sensor ``--sim``), a value drawn from ``(seed, k)`` for the
    others."""
    if k == 0:
        return int(seed)
    return int(np.random.SeedSequence([int(seed), int(k), 0x91A7E]).generate_state(1)[0])


def build_sim_plate(cfg: Config, *, seed: int = 0, noise_seed: int | None = None,
                    mount_deg: float = 3.0, **options: Any) -> list[SimJig]:
    """Every sensor of ``cfg.imus()`` on one emulated jig, in the config's order.

    The first is :func:`build_sim`'s (same ``seed``, same truth as a one-sensor run); the
    ``k``-th draws its truth and its mount misalignment from :func:`plate_seed` ``(seed, k)``
    and sits :data:`SIM_PLATE_PITCH_M` further along the plate (its own lever arm). Sensors on
    the same ``bus`` number share one emulated bus. All share the clock, the servos and the
    joint axes; each :class:`SimJig` is one sensor's view, with its own truth and chip.

    Parameters
    ----------
    cfg : Config
    seed, noise_seed, mount_deg
        As for :func:`build_sim`.
    **options
        :func:`build_sim`'s other keywords (not ``scale`` or ``bias`` with several sensors: each
        sensor draws its own).

    Raises
    ------
    InputError
        If ``scale`` or ``bias`` is fixed for more than one sensor.
    """
    sensors = cfg.imus()
    fixed = [k for k in ("scale", "bias") if options.get(k) is not None]
    if len(sensors) > 1 and fixed:
        raise InputError(f"--sim-{fixed[0]} fixes one sensor's truth; with {len(sensors)} "
                         "sensors on the plate each draws its own by --sim-seed")
    first = build_sim(cfg, seed=seed, noise_seed=noise_seed, mount_deg=mount_deg, **options)
    out = [first]
    buses = {sensors[0]["bus"]: first.imu_bus}
    run_seed = seed if noise_seed is None else noise_seed
    g = cfg["gimbal"]
    for k, sensor in enumerate(sensors[1:], start=1):
        sk = plate_seed(seed, k)
        rng = np.random.default_rng([sk, 0x3047])
        axis = rng.normal(size=3)
        mount = axis / np.linalg.norm(axis) * math.radians(mount_deg)
        arm = (np.asarray(SIM_LEVER_ARM_M) + k * np.asarray(SIM_PLATE_PITCH_M)
               if "gravity" in first.realism else np.zeros(3))
        # the same seed draws the same joint-axis tilts as the first sensor's jig: one gimbal
        jig = GimbalJig(first.servo_bus.servos, axes=g["axes"], mount=mount, seed=seed,
                        wobble_deg=SIM_WOBBLE_DEG if "wobble" in first.realism else 0.0,
                        lever_arm_m=tuple(arm))
        plate = replace(first, jig=jig)
        truth = sim_truth(sk, sensor=options.get("sensor", SIM_SENSOR),
                          family=READERS[sensor["model"]].family.name)
        view = _add_sensor(plate, sensor, sk, plate_seed(run_seed, k), truth,
                           cross_axis=options.get("cross_axis"),
                           noise_density=options.get("noise_density_rad_s_sqrt_hz"),
                           temperature=options.get("temperature"),
                           self_heating=options.get("self_heating"),
                           bus=buses.get(sensor["bus"]))
        buses.setdefault(sensor["bus"], view.imu_bus)
        out.append(view)
    if len(out) > 1:
        first.plate = out
    return out


def sim_thermal(seed: int, model: str, temperature: str | None, self_heating: str | None,
                power_on_s: float = 0.0) -> dict[str, Any]:
    """The emulated sensor's thermal truth (``SensorTruth`` keywords): the die temperature
    (ambient ``temperature``, default 25 °C, plus the self-heating warm-up ``DT[:TAU]``, default
    :data:`~gyrocal.drivers.emulated.thermal.SELF_HEATING_C` over
    :data:`~gyrocal.drivers.emulated.thermal.SELF_HEATING_TAU_S`) and the coefficients drawn by
    ``seed`` within the model's datasheet (:mod:`gyrocal.drivers.emulated.thermal`).

    Raises
    ------
    InputError
        If a profile or the self-heating is malformed (the message shows the forms).
    """
    from gyrocal.drivers.emulated import thermal

    try:
        ambient = thermal.parse_ambient("25" if temperature is None else temperature)
    except ValueError as exc:
        raise InputError(f"--sim-temperature: {exc}") from None
    heat = [thermal.SELF_HEATING_C, thermal.SELF_HEATING_TAU_S]
    if self_heating is not None:
        try:
            given = [float(x) for x in self_heating.split(":")]
            if not 1 <= len(given) <= 2:
                raise ValueError
        except ValueError:
            raise InputError(f"--sim-self-heating {self_heating!r}: use DT or DT:TAU (°C above "
                             "ambient, time constant in s; e.g. 4:180)") from None
        heat[:len(given)] = given
    try:
        die = thermal.DieTemperature(ambient, heat[0], heat[1], power_on_s)
        coeffs = thermal.draw_thermal_coefficients(seed, model)
    except ValueError as exc:
        raise InputError(f"--sim-self-heating: {exc}") from None
    return {"temperature_c": die, "reference_temperature_c": 25.0,
            **{k: tuple(v) for k, v in coeffs.items()}}


#: ``--sim-fault`` kinds: what each takes, what it does.
FAULTS: dict[str, tuple[str, str]] = {
    "stall": ("SERVO:AT[:FRACTION[:DURATION]]",
              "servo reaches only FRACTION (default 0.5) of its speed, for DURATION s (default: "
              "for good)"),
    "silent": ("SERVO:AT", "servo stops answering"),
    "alert": ("SERVO:AT[:BITS]", "servo raises a hardware error (default overload, 32)"),
    "slip": ("AT:DEG", "the sensor's mount slips by DEG degrees"),
    "fifo": ("CAPACITY", "a FIFO of CAPACITY bytes (MPU, ICM), slots (LSM9DS1) or words "
             "(LSM6DSOX): overflows"),
    "nack": ("PROBABILITY", "the IMU refuses I2C messages at random"),
    "imu-dead": ("AT", "the IMU stops answering"),
    "pause": ("AT:SECONDS", "the host stalls for SECONDS at AT: no servo poll, no FIFO drain "
              "(the emulated clock only)"),
    "imu-chip": ("MODEL", "the board carries a MODEL chip instead of the configured one"),
    "seat": ("N", "the single-servo jig's user seats the cube wrong (a quarter turn off) at "
             "the N-th prompt (0-based)"),
}


def fault_help() -> str:
    """One line per ``--sim-fault`` kind."""
    return "; ".join(f"{k}:{args} ({what})" for k, (args, what) in FAULTS.items())


def apply_fault(sim: SimJig, spec: str, t0: float = 0.0) -> str:
    """Arm one fault knob of the emulated jig from a ``KIND:ARGS`` spec; returns a description.

    Times (``AT``) are seconds after ``t0`` on the emulated jig's clock; the kit arms faults
    when the protocol starts, with ``t0`` the start of the recording clock, so ``AT`` is a time
    in the recording.

    Raises
    ------
    InputError
        If the kind is unknown or its arguments are malformed.
    """
    kind, _, rest = spec.partition(":")
    if kind not in FAULTS:
        raise InputError(f"--sim-fault {spec!r}: unknown kind {kind!r}; {fault_help()}")
    parts = [p for p in rest.split(":") if p] if rest else []
    usage = f"--sim-fault {kind}:{FAULTS[kind][0]}"

    def at(i: int) -> float:
        return t0 + num(i)

    def num(i: int, cast: type = float, default: Any = None) -> Any:
        if i >= len(parts):
            if default is None:
                raise InputError(f"--sim-fault {spec!r}: missing arguments; use {usage}")
            return default
        try:
            return cast(parts[i])
        except ValueError:
            raise InputError(f"--sim-fault {spec!r}: {parts[i]!r} is not a number; use {usage}"
                             ) from None

    def servo(i: int) -> Any:
        sid = num(i, int)
        try:
            return sim.servo_bus.servo(sid)
        except (KeyError, ValueError, LookupError):
            raise InputError(f"--sim-fault {spec!r}: no servo {sid} on the emulated jig") from None

    if kind == "stall":
        frac = num(2, float, 0.5)
        s = servo(0)
        s.stall_at(at(1), frac)
        if len(parts) > 3:
            s.clear_stall_at(at(1) + num(3))
            return (f"servo {parts[0]} stalls to {frac:.0%} of its speed at {num(1):g} s for "
                    f"{num(3):g} s")
        return f"servo {parts[0]} stalls to {frac:.0%} of its speed at {num(1):g} s"
    if kind == "silent":
        servo(0).go_silent(at(1))
        return f"servo {parts[0]} stops answering at {num(1):g} s"
    if kind == "alert":
        servo(0).raise_alert_at(at(1), num(2, int, 32))
        return f"servo {parts[0]} raises hardware error bits {num(2, int, 32)} at {num(1):g} s"
    if kind == "slip":
        deg = num(1)
        axis = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
        sim.jig.slip_at(at(0), axis * math.radians(deg), 0.05)
        return f"the mount slips by {deg:g}° at {num(0):g} s"
    if kind == "pause":
        if not hasattr(sim.clock, "stall_at"):
            raise InputError(f"--sim-fault {spec!r}: a pause needs the emulated clock (drop "
                             "--realtime)")
        if not (math.isfinite(at(0)) and math.isfinite(num(1)) and 0 <= num(1) <= 60):
            raise InputError(f"--sim-fault {spec!r}: AT must be finite and SECONDS in 0..60")
        sim.clock.stall_at(at(0), num(1))
        return f"the host stalls for {num(1):g} s at {num(0):g} s"
    if kind == "imu-chip":
        return _swap_imu(sim, spec, parts[0] if parts else "")
    if kind == "seat":
        sim.wrong_seats.add(num(0, int))
        return f"the cube is seated wrong at prompt {num(0, int)}"
    chip = sim.chip
    if kind == "fifo":
        chip.faults.fifo_capacity = num(0, int)
        return f"the IMU FIFO holds only {parts[0]}"
    if kind == "nack":
        chip.faults.nack_probability = num(0)
        return f"the IMU refuses {num(0):.1%} of I2C messages"
    chip.faults.dead_after_s = at(0)
    return f"the IMU stops answering at {num(0):g} s"


def _swap_imu(sim: SimJig, spec: str, model: str) -> str:
    """Replace the emulated IMU (and any magnetometer die) by a ``model`` chip with the same
    motion and truth, at the configured address if that model can have it, else its default."""
    key = model.strip().lower().replace("-", "")
    if key not in READERS:
        raise InputError(f"--sim-fault {spec!r}: unknown IMU model {model!r}; choose one of "
                         + ", ".join(READERS))
    old = sim.chip
    for address in sim.imu_bus.addresses:
        sim.imu_bus.detach(address)
    possible = READERS[key].family.addresses
    address = sim.imu_address if sim.imu_address in possible else possible[0]
    make_emulated_imu(key, old.clock, old.motion, old.truth, bus=sim.imu_bus, address=address)
    return f"the board carries an {READERS[key].family.title} at 0x{address:02X}"


#: The hand jig's emulated stop repeatability and axis wobble, degrees (``--jig hand``:
#: hardware_docs/hand-jig.md, what to expect of a box turned by hand against a firm edge).
HAND_STOP_DEG = 0.1
HAND_WOBBLE_DEG = 1.0


def build_hand_sim(cfg: Config, *, seed: int = 0, noise_seed: int | None = None,
                   mount_deg: float = 3.0, lead_s: float = 1.0, schedule: Any = None,
                   **options: Any) -> SimJig:
    """The emulated hand jig (``--sim --jig hand``): the configured IMU on a box turned by a
    hand (:class:`gyrocal.drivers.emulated.hand.HandMotion`: irregular speed within each turn,
    rests of varying length, a wobbling axis, the stop's repeatability), no servos.

    Parameters
    ----------
    cfg : Config
    seed, noise_seed, mount_deg
        As for :func:`build_sim` (``seed`` draws the sensor, the mount on the box and the
        hand's schedule; ``noise_seed`` the noise and the hand's speed profiles).
    lead_s : float
        Still time before the schedule starts (the reader's start-up), s.
    schedule : list of HandPhase, optional
        The hand's schedule (default: :func:`~gyrocal.drivers.emulated.hand.hand_schedule`
        drawn by ``seed``).
    **options
        :func:`build_sim`'s ``scale``, ``bias``, ``cross_axis``, ``realism``, ``temperature``,
        ``self_heating``, ``sensor``, ``noise_density_rad_s_sqrt_hz``.
    """
    from gyrocal.drivers.emulated.hand import HandMotion, hand_schedule

    clock = VirtualClock()
    run_seed = seed if noise_seed is None else noise_seed
    realism = options.get("realism")
    effects = frozenset(REALISM_EFFECTS if realism is None else realism)
    rng = np.random.default_rng([int(seed), 0x4A4F])
    axis = rng.normal(size=3)
    schedule = hand_schedule(seed) if schedule is None else schedule
    motion = HandMotion(schedule, t0=clock.monotonic() + lead_s,
                        mount=tuple(axis / np.linalg.norm(axis) * math.radians(mount_deg)),
                        wobble_deg=HAND_WOBBLE_DEG if "wobble" in effects else 0.0,
                        stop_deg=HAND_STOP_DEG, seed=run_seed)
    plate = SimJig(clock, None, None, motion, None, 0, SensorTruth(), effects)
    family = READERS[cfg["imu"]["model"]].family.name
    truth = sim_truth(seed, options.get("scale"), options.get("bias"),
                      sensor=options.get("sensor") or SIM_SENSOR, family=family)
    return _add_sensor(plate, cfg["imu"], seed, run_seed, truth,
                       cross_axis=options.get("cross_axis"),
                       noise_density=options.get("noise_density_rad_s_sqrt_hz"),
                       temperature=options.get("temperature"),
                       self_heating=options.get("self_heating"))
