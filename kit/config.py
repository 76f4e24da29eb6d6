"""The ``gyrocal.toml`` configuration: the jig, the sensor, the protocol.

Every key is declared once in :data:`SCHEMA` with its type, default, allowed values and help text;
:func:`load_config` rejects unknown keys and bad values naming the key and what is allowed, and
``gyrocal init`` writes :func:`template` (every key, commented). Command-line flags override the
file through :func:`apply_overrides`.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gyrocal.drivers.imu import MODELS as IMU_MODELS
from gyrocal.kit.choices import METHODS, PROTOCOLS
from gyrocal.kit.errors import InputError

__all__ = [
    "MAX_SENSORS",
    "METHODS",
    "PROTOCOLS",
    "SCHEMA",
    "Config",
    "apply_overrides",
    "default_config",
    "load_config",
    "template",
]



#: A gyrocal.toml is a few kB; anything far larger is a wrong file.
_MAX_CONFIG_BYTES = 1 << 20


@dataclass(frozen=True)
class Key:
    """One configuration key."""

    default: Any
    help: str
    kind: type | tuple[type, ...]
    choices: tuple[Any, ...] | None = None
    check: Callable[[Any], str | None] | None = None


def _within(lo: float, hi: float, *, zero: str | None = None) -> Callable[[Any], str | None]:
    """A check: a finite number in ``lo..hi`` (or exactly 0 when ``zero`` says what 0 means)."""
    def check(v: Any) -> str | None:
        if isinstance(v, float) and not math.isfinite(v):
            return f"must be a finite number in {lo:g}..{hi:g}"
        if zero is not None and v == 0:
            return None
        if not lo <= v <= hi:  # exact for integers of any size
            return f"must be in {lo:g}..{hi:g}" + (f" (or 0: {zero})" if zero else "")
        return None
    return check


def _axes(v: Any) -> str | None:
    if not isinstance(v, list) or not all(isinstance(a, str) for a in v):
        return "must be a list of axis names like [\"x\", \"y\", \"z\"] (a sign is allowed: \"-y\")"
    bad = [a for a in v if a.lstrip("+-") not in ("x", "y", "z") or len(a) > 2]
    if bad:
        return f"has unknown axes {bad}; use x, y, z with an optional sign"
    if len(v) == 3 and sorted(a.lstrip("+-") for a in v) != ["x", "y", "z"]:
        return "must name each of x, y and z once"
    return None


def _ids(v: Any) -> str | None:
    if not isinstance(v, list) or not v or not all(isinstance(i, int) and not isinstance(i, bool)
                                                   for i in v):
        return "must be a non-empty list of integer servo IDs"
    if len(set(v)) != len(v) or not all(0 <= i <= 252 for i in v):
        return "must be distinct IDs in 0..252"
    return None


def _address(v: Any) -> str | None:
    if v == 0 or 0x03 <= v <= 0x77:
        return None
    return "must be a 7-bit I2C address (0x03..0x77), or 0 for the chip's own"


def _history(what: str) -> Callable[[Any], str | None]:
    """A check of a ``[history]`` value by :mod:`gyrocal.kit.history` ("" is always allowed)."""
    def check(v: Any) -> str | None:
        from gyrocal.kit.history import HistoryError, check_label, check_url

        try:
            if v:
                (check_url if what == "url" else check_label)(v, "")
        except HistoryError as exc:
            return str(exc).strip()
        return None
    return check


SCHEMA: dict[str, dict[str, Key]] = {
    "gimbal": {
        "port": Key("/dev/ttyUSB0", "serial device of the U2D2 (or any Dynamixel interface)", str),
        "baud": Key(57600, "bus speed the servos are set to (factory: 57600)", int,
                    (9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000)),
        "ids": Key([1, 2, 3], "servo IDs, base to tip", list, check=_ids),
        "axes": Key(["x", "y", "z"],
                    "sensor axis each servo turns about in the home pose, same order as ids",
                    list, check=_axes),
        # Extended Position mode holds ±256 turns (hardware reference §5)
        "max_turns": Key(3.0, "software cable-wrap limit: turns from home, either way (0.1..256)",
                         (int, float), check=_within(0.1, 256)),
        "acceleration": Key(10.0, "profile acceleration of every turn, rad/s^2 (0.5..500)",
                            (int, float), check=_within(0.5, 500)),
        "sample_hz": Key(200.0, "loop rate: IMU drains and servo sync reads per second (10..1000)",
                         (int, float), check=_within(10, 1000)),
        "watchdog_s": Key(0.3, "Bus Watchdog armed while a servo moves: a servo that gets no "
                          "packet this long stops by itself, s (0.02..2.54, 20 ms steps)",
                          (int, float), check=_within(0.02, 2.54)),
        "retries": Key(3, "resends of a servo transaction whose status packet was lost or late "
                       "before it is an error (0..50)", int, check=_within(0, 50)),
    },
    "imu": {
        "model": Key("mpu9250", "sensor chip", str, IMU_MODELS),
        "bus": Key(1, "I2C bus number: /dev/i2c-N (0..1023)", int, check=_within(0, 1023)),
        "address": Key(0, "7-bit I2C address (MPU-9250, ICM-20948, ICM-42688-P: 0x68/0x69; "
                       "LSM9DS1 A/G, LSM6DSOX: 0x6A/0x6B); 0: the chip's own (the one of its "
                       "addresses where it answers; its first on the emulated jig)",
                       int, check=_address),
        "range_dps": Key(500, "gyro full-scale range, degrees per second", int,
                         (245, 250, 500, 1000, 2000)),
        "odr_hz": Key(200.0, "gyro output data rate, Hz (1..8000); the chip runs at the "
                      "nearest rate it has (a note says which)", (int, float),
                      check=_within(1, 8000)),
    },
    "protocol": {
        "name": Key(PROTOCOLS[0], "full: planned with poses for the full matrix (three "
                    "servos, at least 45 s); auto: planned for this servo and gyro, diagonal "
                    "model only; paper: 60 deg/s, one turn, 3 s waits", str, PROTOCOLS),
        "time_budget_s": Key(0.0, "longest jig time the planner may use, s (1..3600; 0: the "
                             "protocol's own, 45 s for full, 30 s for auto; full takes at least "
                             "45 s whatever is set)", (int, float),
                             check=_within(1, 3600, zero="the protocol's own")),
        "speed_dps": Key(0.0, "fixed turn speed, deg/s (1..2000; 0: planned)", (int, float),
                         check=_within(1, 2000, zero="planned")),
        "turns": Key(0, "fixed whole turns per direction (1..256; 0: planned)", int,
                     check=_within(1, 256, zero="planned")),
        "rest_s": Key(0.0, "fixed rest before each turn, s (0.1..600; 0: planned)", (int, float),
                      check=_within(0.1, 600, zero="planned")),
        "method": Key(METHODS[0], "estimator", str, METHODS),
        "accel_rests": Key(True, "tilt the rests between turns so the accelerometer is "
                           "calibrated too (protocol full; a few moves, about 8 s on the "
                           "default run); false: rests in the gyro's poses only", bool),
        "align_gyro_to_accel": Key(False, "express the gyro calibration in the calibrated "
                                   "accelerometer's frame (accel-x-xy), as imu_tk does", bool),
    },
    "accelerometer": {
        # the accelerometer is fitted to |f| = g on the rests (calib.accel): the local gravity
        # magnitude is an input; standard gravity is off the local value by up to 0.3 %, which
        # the fit then puts into the scales
        "gravity_m_s2": Key(9.80665, "local gravity magnitude for the accelerometer fit, m/s^2 "
                            "(9.7..9.9; default standard gravity 9.80665; 0: WGS-84 normal "
                            "gravity at latitude_deg and height_m)", (int, float),
                            check=_within(9.7, 9.9, zero="from latitude_deg and height_m")),
        "latitude_deg": Key(0.0, "geodetic latitude of the jig, degrees (-90..90; used when "
                            "gravity_m_s2 = 0)", (int, float), check=_within(-90, 90)),
        "height_m": Key(0.0, "height of the jig above the WGS-84 ellipsoid, m (-1000..20000; "
                        "used when gravity_m_s2 = 0)", (int, float),
                        check=_within(-1000, 20000)),
    },
    "history": {
        "url": Key("", "calibration history (kit/history.py): sqlite:///PATH or "
                   "postgresql://USER@HOST/DB; calibrate stores every calibration there "
                   "(\"\": only with --history)", str, check=_history("url")),
        "sensor_label": Key("", "the label of the sensor on the jig, its key in the history "
                            "(\"\": give --sensor-label)", str, check=_history("label")),
        "jig": Key("", "this jig's name in the history (\"\": the host name)", str,
                   check=_history("label")),
    },
}


#: The most sensors one run may carry (``[[imu]]`` tables): each is drained every loop
#: iteration, and ``python -m bench multi`` measures the loop with up to four.
MAX_SENSORS = 8
#: A sensor's name (``[[imu]]`` key ``name``) is the name of its output directory.
_SENSOR_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,39}")


@dataclass(frozen=True)
class Config:
    """A validated configuration: ``sections[section][key]``, plus where it came from.

    ``sections["imu"]`` is the (first) sensor; ``sensors`` lists every sensor of a plate given
    as ``[[imu]]`` tables (each the ``[imu]`` keys plus ``name``), empty for a single ``[imu]``.
    """

    sections: dict[str, dict[str, Any]]
    source: str
    sensors: tuple[dict[str, Any], ...] = ()

    def __getitem__(self, section: str) -> dict[str, Any]:
        return self.sections[section]

    def imus(self) -> list[dict[str, Any]]:
        """Every sensor of the run as ``[imu]`` keys plus ``name``, in the config's order (a
        single ``[imu]`` table is one sensor named ``imu``)."""
        if self.sensors:
            return [dict(s) for s in self.sensors]
        return [{**self.sections["imu"], "name": "imu"}]

    def axis_of(self) -> dict[int, str]:
        """``{servo id: signed sensor axis}`` from gimbal.ids and gimbal.axes."""
        return dict(zip(self["gimbal"]["ids"], self["gimbal"]["axes"], strict=True))


def default_config() -> Config:
    """Every key at its default."""
    return Config({s: {k: key.default for k, key in keys.items()} for s, keys in SCHEMA.items()},
                  "defaults")


def _excerpt(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (a 400-digit number is not quoted whole)."""
    text = repr(value) if not isinstance(value, int) or abs(value) < 10 ** 40 else (
        f"an integer of {len(str(abs(value)))} digits")
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _cut(name: str, limit: int = 60) -> str:
    """A key or section name as typed, cut to ``limit`` characters (a damaged file's 5000-
    character "key" is not quoted whole)."""
    return name if len(name) <= limit else name[: limit - 1] + "…"


def _validate(section: str, name: str, value: Any) -> Any:
    key = SCHEMA[section][name]
    kinds = key.kind if isinstance(key.kind, tuple) else (key.kind,)
    ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
    if not ok:
        want = " or ".join(k.__name__ for k in kinds)
        raise InputError(f"config key {section}.{name} must be {want}, got {_excerpt(value)}")
    if key.choices is not None and value not in key.choices:
        allowed = ", ".join(repr(c) for c in key.choices)
        raise InputError(f"config key {section}.{name} is {_excerpt(value)}; allowed: {allowed}")
    if key.check is not None:
        problem = key.check(value)
        if problem:
            shown = f"{value:#04x}" if name == "address" else _excerpt(value)  # hex as i2cdetect
            raise InputError(f"config key {section}.{name} {problem} (got {shown})")
    return value


def _default_address(sensor: Mapping[str, Any]) -> int:
    """The sensor's address, its chip's default (:func:`gyrocal.drivers.imu.chip_addresses`)
    when ``address`` is 0."""
    from gyrocal.drivers.imu import chip_addresses

    return int(sensor["address"]) or chip_addresses(sensor["model"])[0]


def _sensor_list(tables: list[Any], source: str) -> tuple[dict[str, Any], ...]:
    """The ``[[imu]]`` tables validated: each over the ``[imu]`` defaults, named, and at its own
    address on its bus."""
    if not 1 <= len(tables) <= MAX_SENSORS:
        raise InputError(f"{source}: [[imu]] lists {len(tables)} sensors; give 1 to "
                         f"{MAX_SENSORS}")
    defaults = default_config()["imu"]
    out: list[dict[str, Any]] = []
    for i, table in enumerate(tables):
        where = f"{source}: [[imu]] number {i + 1}"
        if not isinstance(table, Mapping):
            raise InputError(f"{where} must be a table of keys")
        sensor = dict(defaults)
        for name, value in table.items():
            if name == "name":
                if not isinstance(value, str) or not _SENSOR_NAME.fullmatch(value):
                    raise InputError(
                        f"{where}: name {_excerpt(value)} must be 1-40 letters, digits, '_', "
                        "'.' or '-' (it names the sensor's output directory)")
                continue
            if name not in SCHEMA["imu"]:
                raise InputError(f"{where}: unknown key {_cut(name)}; allowed: name, "
                                 + ", ".join(SCHEMA["imu"]))
            sensor[name] = _validate("imu", name, value)
        sensor["name"] = table.get("name", f"{sensor['model']}-{sensor['bus']}-"
                                           f"{_default_address(sensor):02x}")
        out.append(sensor)
    seen: dict[Any, str] = {}
    for s in out:
        for key, what in (((s["bus"], _default_address(s)), "the same I2C bus and address"),
                          (s["name"].lower(), "the same name")):
            if key in seen:
                raise InputError(
                    f"{source}: sensors {seen[key]!r} and {s['name']!r} have {what}: give each "
                    "sensor its own address (or bus), and each a distinct name")
            seen[key] = s["name"]
    return tuple(out)


def _merge(base: Config, data: Mapping[str, Any], source: str) -> Config:
    sections = {s: dict(v) for s, v in base.sections.items()}
    sensors = base.sensors
    if isinstance(data.get("imu"), list):  # [[imu]] tables: several sensors on the plate
        sensors = _sensor_list(data["imu"], source)
        sections["imu"] = {k: v for k, v in sensors[0].items() if k != "name"}
        data = {k: v for k, v in data.items() if k != "imu"}
    elif "imu" in data and sensors:
        if len(sensors) > 1:
            raise InputError(
                f"{source}: the config lists {len(sensors)} sensors as [[imu]] tables; the "
                "--imu-* and --range-dps/--odr flags set a single sensor: edit each [[imu]] "
                "table instead")
        sensors = ()
    for section, values in data.items():
        if section not in SCHEMA:
            raise InputError(
                f"{source}: unknown section [{_cut(section)}]; allowed: {', '.join(SCHEMA)}"
            )
        if not isinstance(values, Mapping):
            raise InputError(f"{source}: [{section}] must be a table of keys")
        for name, value in values.items():
            if name not in SCHEMA[section]:
                raise InputError(
                    f"{source}: unknown key {section}.{_cut(name)}; allowed in [{section}]: "
                    f"{', '.join(SCHEMA[section])}"
                )
            sections[section][name] = _validate(section, name, value)
    # "+y" means "y": one spelling for the validator and everything downstream
    sections["gimbal"]["axes"] = [a.removeprefix("+") for a in sections["gimbal"]["axes"]]
    cfg = Config(sections, source, sensors)
    g = cfg["gimbal"]
    if len(g["ids"]) != len(g["axes"]):
        raise InputError(
            f"{source}: gimbal.ids has {len(g['ids'])} servos but gimbal.axes names "
            f"{len(g['axes'])} axes; give one axis per servo"
        )
    return cfg


#: Most parts a key of gyrocal.toml may have (``[section]`` and ``key``, or ``section.key``:
#: two; a little room for quoting). A dotted key of tens of thousands of parts costs the TOML
#: parser gigabytes, so it is refused before parsing.
MAX_KEY_PARTS = 8


def _check_key_depth(text: str, where: str) -> None:
    """Refuse a key (a table header or the left of ``=``) of more than :data:`MAX_KEY_PARTS`
    dot-separated parts, by line, before the TOML parser sees it. Dots inside quotes and the
    lines of multi-line strings are not counted.

    Raises
    ------
    InputError
    """
    in_multiline: str | None = None
    for number, line in enumerate(text.splitlines(), 1):
        if in_multiline is not None:
            if line.count(in_multiline) % 2 == 1:
                in_multiline = None
            continue
        key, quote, dots = line, None, 0
        if "=" in line and not line.lstrip().startswith("["):
            key = line.split("=", 1)[0]
            value = line.split("=", 1)[1]
            for delim in ('"""', "\'\'\'"):
                if value.count(delim) % 2 == 1:
                    in_multiline = delim
        for ch in key:
            if quote is not None:
                quote = None if ch == quote else quote
            elif ch in "\"'":
                quote = ch
            elif ch == "#":
                break
            elif ch == ".":
                dots += 1
        if dots + 1 > MAX_KEY_PARTS:
            raise InputError(f"{where}, line {number}: a key of {dots + 1} dotted parts; "
                             f"gyrocal.toml's keys have at most {MAX_KEY_PARTS} (section.key)")


def load_config(path: str | os.PathLike[str] | None) -> Config:
    """Read ``path`` (TOML) over the defaults; None gives the defaults.

    Raises
    ------
    InputError
        If the file is missing or not TOML, or a section, key or value is not allowed.
    """
    if path is None:
        return default_config()
    p = Path(path)
    if p.is_dir():
        raise InputError(
            f"--config {p} is a directory; give the config file itself (e.g. {p / 'gyrocal.toml'})")
    if p.exists() and not p.is_file():
        raise InputError(f"config file {p} is not a regular file; give the path of a TOML file")
    try:
        if p.stat().st_size > _MAX_CONFIG_BYTES:
            raise InputError(f"config file {p} is larger than {_MAX_CONFIG_BYTES} bytes: not a "
                             "gyrocal.toml")
        text = p.read_text(encoding="utf-8")
        _check_key_depth(text, str(p))
        data = tomllib.loads(text)
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"config file {p} not found; `gyrocal init` writes one") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{p} is not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    except PermissionError:
        raise InputError(f"cannot read config file {p}: permission denied") from None
    except RecursionError:
        raise InputError(f"{p}: arrays or tables nested too deeply; not a gyrocal.toml") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p} is not valid TOML: {exc}") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise InputError(f"{p}: a value cannot be read ({str(exc)[:80]})") from None
    except OSError as exc:
        raise InputError(f"cannot read config file {p}: {exc.strerror or exc}") from None
    return _merge(default_config(), data, str(p))


def apply_overrides(cfg: Config, overrides: Mapping[str, Any]) -> Config:
    """``cfg`` with ``{"section.key": value}`` overrides (from flags; None values are skipped)."""
    data: dict[str, dict[str, Any]] = {}
    for dotted, value in overrides.items():
        if value is None:
            continue
        section, name = dotted.split(".", 1)
        data.setdefault(section, {})[name] = value
    return _merge(cfg, data, f"{cfg.source} + command line")


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def template(model: str | None = None) -> str:
    """A commented ``gyrocal.toml`` with every key at its default; with ``model``, the
    ``[imu]`` of that chip: its default address (:func:`gyrocal.drivers.imu.chip_addresses`)
    and the rate it has nearest the default (:func:`gyrocal.drivers.imu.nearest_offered_rate`).
    """
    values = {s: {k: key.default for k, key in keys.items()} for s, keys in SCHEMA.items()}
    if model is not None:
        from gyrocal.drivers.imu import chip_addresses, nearest_offered_rate

        values["imu"].update(model=_validate("imu", "model", model),
                             address=chip_addresses(model)[0],
                             odr_hz=nearest_offered_rate(model, values["imu"]["odr_hz"]))
    lines = [
        "# gyrocal configuration. Every key is optional; shown here at its default.",
        "# Command-line flags override these values. See hardware_docs/running.md.",
    ]
    for section, keys in SCHEMA.items():
        lines += ["", f"[{section}]"]
        for name, key in keys.items():
            lines.append(f"# {key.help}")
            if key.choices is not None:
                lines.append(f"# allowed: {', '.join(_toml_value(c) for c in key.choices)}")
            value = _toml_value(values[section][name])
            if name == "address" and values[section][name]:
                value = hex(values[section][name])
            lines.append(f"{name} = {value}")
    lines += ["", "# Several sensors on the plate (hardware_docs/running.md): replace [imu] by one",
              "# [[imu]] table per sensor, each with the [imu] keys and a name, e.g.",
              "# [[imu]]", '# name = "a"', '# model = "mpu9250"', "# address = 0x68",
              "# [[imu]]", '# name = "b"', '# model = "icm42688p"', "# address = 0x69"]
    return "\n".join(lines) + "\n"
