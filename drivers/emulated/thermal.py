"""The emulated chip's die temperature and its temperature coefficients (issue 13).

Die temperature
    ``T_die(t) = ambient(t) + ΔT_self · (1 − exp(−(t − t_on) / τ))`` for ``t ≥ t_on``: the
    ambient the user sets (:func:`parse_ambient`) plus a first-order self-heating warm-up from
    power-on at ``t_on`` (a MEMS die dissipating a few mW in a small package settles a few °C
    above its surroundings within minutes; ΔT_self and τ are set per jig, defaults
    :data:`SELF_HEATING_C` and :data:`SELF_HEATING_TAU_S`).

Ambient profiles (``--sim-temperature``), all temperatures in °C and times in seconds from
power-on:

``T``
    constant ``T`` (``25``);
``ramp:T0:T1:S``
    ``T0`` rising (or falling) linearly to ``T1`` over ``S`` seconds, then ``T1``;
``soak:T0:T1:TAU``
    a cold-soaked (or heat-soaked) sensor: starts at ``T0`` and approaches ``T1``
    exponentially with time constant ``TAU``.

Coefficients (:func:`draw_thermal_coefficients`) are drawn per seed within the datasheets'
temperature ranges (:data:`THERMAL_DATASHEET`): the bias gets a linear and a quadratic term in
``(T − reference)``, each axis's scale a relative linear coefficient, so that over the rated
range neither exceeds the datasheet's total change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "SELF_HEATING_C",
    "SELF_HEATING_TAU_S",
    "THERMAL_DATASHEET",
    "AmbientProfile",
    "DieTemperature",
    "ThermalSpec",
    "draw_thermal_coefficients",
    "parse_ambient",
    "per_degree",
]

_RAD_PER_DEG = math.pi / 180.0

#: Default self-heating of the emulated die above ambient, °C, and its time constant, s.
SELF_HEATING_C = 4.0
SELF_HEATING_TAU_S = 180.0


@dataclass(frozen=True)
class ThermalSpec:
    """A gyro datasheet's temperature figures.

    Attributes
    ----------
    zro_change_dps : float
        Largest zero-rate (bias) change over the operating range, ±°/s.
    sensitivity_change : float
        Largest sensitivity change over the operating range, ± fraction.
    range_c : (float, float)
        The operating range the two figures are given over, °C.
    source : str
        Where the figures come from (⚠ marks a figure not checked against a second source).
    """

    zro_change_dps: float
    sensitivity_change: float
    range_c: tuple[float, float]
    source: str

    @property
    def span_c(self) -> float:
        """Width of the operating range, °C."""
        return self.range_c[1] - self.range_c[0]


def per_degree(zro_dps_per_c: float, sensitivity_pct_per_c: float,
               range_c: tuple[float, float], source: str) -> ThermalSpec:
    """A :class:`ThermalSpec` from a datasheet that gives per-°C figures ("zero-rate level change
    vs. temperature", dps/°C; "sensitivity change vs. temperature", %/°C): the change over the
    range is the figure times half its width (from a reference in the middle), so that the
    drawn linear coefficient stays within ¾ of the datasheet's per-°C figure."""
    half = (range_c[1] - range_c[0]) / 2.0
    return ThermalSpec(zro_dps_per_c * half, sensitivity_pct_per_c / 100.0 * half, range_c,
                       source)


#: Temperature figures by chip model (hardware facts as data). ⚠ marks a figure found in one
#: source only (or in sources that disagree), to be checked against the manufacturer's PDF.
THERMAL_DATASHEET: dict[str, ThermalSpec] = {
    # PS-MPU-9250A-01 §3.1, Gyroscope Specifications: "ZRO Variation Over Temperature
    # −40 °C to +85 °C ±30 °/s" and "Sensitivity Scale Factor Variation Over Temperature
    # −40 °C to +85 °C ±4 %".
    "mpu9250": ThermalSpec(30.0, 0.04, (-40.0, 85.0), "PS-MPU-9250A-01 §3.1"),
    # LSM9DS1 (DocID025715) Table 3: angular rate zero-rate level change vs. temperature
    # ±0.03 dps/°C (⚠ single-sourced: the same ±0.03 dps/°C is ST's figure for its other
    # 245-dps gyros, e.g. the I3G4250D, but the LSM9DS1 table was not read here); the gyro's
    # sensitivity change vs. temperature is not given: ±2 % over the range stands in for it
    # (⚠ assumption: the I3G4250D's "SoDr ±2 %" over −40…85 °C).
    "lsm9ds1": ThermalSpec(0.03 * 62.5, 0.02, (-40.0, 85.0),
                           "LSM9DS1 DocID025715 Table 3 (⚠ single-sourced; sensitivity ⚠ "
                           "assumed ±2 %)"),
    # ICM-20948 DS-000189 Table 1, Gyroscope Specifications: "ZRO Variation Over Temperature
    # −40 °C to +85 °C ±0.05 dps/°C" (two sources agree) and "Sensitivity Scale Factor
    # Variation Over Temperature −40 °C to +85 °C ±3 %" (⚠ single-sourced).
    "icm20948": ThermalSpec(0.05 * 62.5, 0.03, (-40.0, 85.0),
                            "ICM-20948 DS-000189 Table 1 (sensitivity ⚠ single-sourced)"),
    # ICM-42688-P DS-000347 Table 1, Gyroscope Specifications: "Sensitivity Scale Factor
    # Variation Over Temperature 0 °C to +70 °C ±0.005 %/°C" and "ZRO Variation vs.
    # Temperature 0 °C to +70 °C ±0.005 dps/°C" (⚠ single-sourced; one secondary table gives
    # 0.05 dps/°C instead).
    "icm42688p": per_degree(0.005, 0.005, (0.0, 70.0),
                            "ICM-42688-P DS-000347 Table 1 (⚠ single-sourced; ZRO figures "
                            "disagree: 0.005 vs 0.05 dps/°C)"),
    # LSM6DSOX (DS12814) Table 2, Mechanical characteristics: "G_OffDr angular rate typical
    # zero-rate level change vs. temperature ±0.01 dps/°C" (⚠ single-sourced; the LSM6DSO32's
    # DocID032891 gives the same) and "G_SoDr angular rate sensitivity change vs.
    # temperature, −40…85 °C" (⚠ not read: the LSM6DSO32's ±0.005 %/°C stands in for it).
    "lsm6dsox": per_degree(0.01, 0.005, (-40.0, 85.0),
                           "LSM6DSOX DS12814 Table 2 (⚠ single-sourced; sensitivity ⚠ "
                           "LSM6DSO32's figure)"),
}
for _alias in ("mpu9255", "mpu6500"):
    THERMAL_DATASHEET[_alias] = THERMAL_DATASHEET["mpu9250"]


@dataclass(frozen=True)
class AmbientProfile:
    """An ambient temperature profile (module docstring); call it with times from power-on.

    Attributes
    ----------
    kind : str
        ``"constant"``, ``"ramp"`` or ``"soak"``.
    start_c, end_c : float
        Temperature at power-on and where it ends (equal for ``constant``).
    seconds : float
        Ramp duration (``ramp``) or time constant (``soak``); 0 for ``constant``.
    """

    kind: str
    start_c: float
    end_c: float
    seconds: float = 0.0

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.maximum(np.asarray(t, dtype=float), 0.0)
        if self.kind == "constant":
            return np.full(t.shape, self.start_c)
        if self.kind == "ramp":
            return self.start_c + (self.end_c - self.start_c) * np.minimum(t / self.seconds, 1.0)
        return self.end_c + (self.start_c - self.end_c) * np.exp(-t / self.seconds)

    def spec(self) -> str:
        """The ``--sim-temperature`` text of this profile."""
        if self.kind == "constant":
            return f"{self.start_c:g}"
        return f"{self.kind}:{self.start_c:g}:{self.end_c:g}:{self.seconds:g}"


_USAGE = ("use T, ramp:T0:T1:SECONDS or soak:T0:T1:TAU (°C and seconds from power-on, "
          "e.g. 25 or ramp:20:30:600)")


def parse_ambient(spec: str) -> AmbientProfile:
    """Parse an ambient profile (module docstring).

    Raises
    ------
    ValueError
        If the text is not one of the forms, a number is malformed, a temperature is outside
        −60…150 °C or a duration is not positive; the message shows the forms.
    """
    parts = str(spec).strip().split(":")
    kind = "constant" if len(parts) == 1 else parts[0]
    nums = parts if len(parts) == 1 else parts[1:]
    if kind not in ("constant", "ramp", "soak") or len(nums) != (1 if kind == "constant" else 3):
        raise ValueError(f"ambient temperature {spec!r} not understood; {_USAGE}")
    try:
        values = [float(x) for x in nums]
    except ValueError:
        raise ValueError(f"ambient temperature {spec!r}: not numbers; {_USAGE}") from None
    temps = values[:1] if kind == "constant" else values[:2]
    if not all(math.isfinite(x) and -60.0 <= x <= 150.0 for x in temps):
        raise ValueError(f"ambient temperature {spec!r}: temperatures must be within "
                         "-60..150 °C")
    if kind == "constant":
        return AmbientProfile("constant", temps[0], temps[0])
    if not (math.isfinite(values[2]) and values[2] > 0):
        raise ValueError(f"ambient temperature {spec!r}: the duration must be positive seconds")
    return AmbientProfile(kind, temps[0], temps[1], values[2])


@dataclass(frozen=True)
class DieTemperature:
    """The die temperature on the shared clock: ambient plus self-heating (module docstring).

    Usable as :attr:`SensorTruth.temperature_c <gyrocal.drivers.emulated.imu_chips.
    SensorTruth.temperature_c>` (vectorised over clock times).

    Attributes
    ----------
    ambient : AmbientProfile
    self_heating_c : float
        Steady rise of the die above ambient, °C (≥ 0).
    time_constant_s : float
        Time constant of the warm-up, s (> 0).
    power_on_s : float
        Clock time of power-on.
    """

    ambient: AmbientProfile
    self_heating_c: float = SELF_HEATING_C
    time_constant_s: float = SELF_HEATING_TAU_S
    power_on_s: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.self_heating_c) and 0.0 <= self.self_heating_c <= 50.0):
            raise ValueError(f"self-heating must be within 0..50 °C, got {self.self_heating_c!r}")
        if not (math.isfinite(self.time_constant_s) and self.time_constant_s > 0):
            raise ValueError(f"the warm-up time constant must be positive seconds, got "
                             f"{self.time_constant_s!r}")

    def __call__(self, t: np.ndarray) -> np.ndarray:
        s = np.maximum(np.asarray(t, dtype=float) - self.power_on_s, 0.0)
        return self.ambient(s) + self.self_heating_c * -np.expm1(-s / self.time_constant_s)

    def manifest(self) -> dict[str, Any]:
        """The die-temperature part of ``truth.temperature`` in a recording's manifest."""
        return {"ambient": self.ambient.spec(), "self_heating_c": self.self_heating_c,
                "time_constant_s": self.time_constant_s, "power_on_s": self.power_on_s}


def draw_thermal_coefficients(seed: int, model: str = "mpu9250",
                              fraction: float = 1.0) -> dict[str, np.ndarray]:
    """Temperature coefficients of one emulated sensor, drawn by ``seed`` within the datasheet.

    Per axis the bias changes by ``c1·dT + c2·dT²`` (``dT = T − 25 °C``) and the scale by the
    factor ``1 + k·dT``. ``c1`` is uniform within ±(¾ of the datasheet's change) / (half the
    range), and ``c2`` is uniform within ±(¼ of it) / (half the range)², so that over the rated
    range the bias never moves by more than the datasheet's ±change; ``k`` is uniform within
    ±change / (half the range). ``fraction`` scales all of them (``0.5`` gives half-datasheet
    sensors).

    Returns
    -------
    dict
        ``bias_temp_coeff_rad_s_per_c`` (3,), ``bias_temp_quad_rad_s_per_c2`` (3,) and
        ``scale_temp_coeff_per_c`` (3,).

    Raises
    ------
    ValueError
        If ``model`` has no entry in :data:`THERMAL_DATASHEET`.
    """
    spec = THERMAL_DATASHEET.get(str(model).lower().replace("-", ""))
    if spec is None:
        raise ValueError(f"no temperature figures for IMU model {model!r}; known: "
                         f"{', '.join(sorted(THERMAL_DATASHEET))}")
    rng = np.random.default_rng([int(seed), 0x7E3])
    half = spec.span_c / 2.0
    zro = spec.zro_change_dps * _RAD_PER_DEG * float(fraction)
    return {
        "bias_temp_coeff_rad_s_per_c": rng.uniform(-0.75, 0.75, 3) * zro / half,
        "bias_temp_quad_rad_s_per_c2": rng.uniform(-0.25, 0.25, 3) * zro / half**2,
        "scale_temp_coeff_per_c": rng.uniform(-1.0, 1.0, 3) * spec.sensitivity_change
        * float(fraction) / half,
    }
