"""The control tables as data, checked against dynamixel-sdk's shipped tables and the datasheet."""

import math
from pathlib import Path

import pytest

from gyrocal.drivers.dynamixel.control_table import (
    COMPATIBLE_MODELS,
    HARDWARE_ERROR_BITS,
    MODELS,
    model_by_name,
)

#: Every item the gimbal driver reads or writes.
DRIVER_ITEMS = [
    "Model Number", "Firmware Version", "Return Delay Time", "Drive Mode", "Operating Mode",
    "Temperature Limit", "Max Voltage Limit", "Min Voltage Limit", "Velocity Limit",
    "Torque Enable", "Hardware Error Status", "Bus Watchdog", "Goal Velocity",
    "Profile Acceleration", "Profile Velocity", "Goal Position", "Realtime Tick", "Moving",
    "Moving Status", "Present PWM", "Present Velocity", "Present Position",
    "Present Input Voltage", "Present Temperature",
]


#: Items of the newest e-manual tables that the SDK's model files predate (hardware reference §5).
NEWER_THAN_SDK_TABLE = {"Backup Ready"}


def _sdk_model_file(name: str) -> dict[str, tuple[int, int]]:
    easy = pytest.importorskip("dynamixel_easy_sdk")
    path = Path(easy.__file__).parent / "control_table" / name
    if not path.exists():
        pytest.skip(f"dynamixel-sdk does not ship {name}")
    items: dict[str, tuple[int, int]] = {}
    in_table = False
    for line in path.read_text().splitlines():
        if line.strip() == "[control table]":
            in_table = True
            continue
        if in_table and line.strip() and line[0].isdigit():
            addr, size, item = line.split("\t")
            items.setdefault(item.strip(), (int(addr), int(size)))
    return items


@pytest.mark.parametrize(("model", "file"), [("XM430-W350", "xm430_w350.model"),
                                             ("XL430-W250", "xl430_w250.model")])
def test_addresses_and_sizes_match_the_sdk_tables(model, file):
    sdk = _sdk_model_file(file)
    table = model_by_name(model).table
    checked = 0
    for item in table.items:
        key = item.name
        if key.startswith("Indirect") or key in NEWER_THAN_SDK_TABLE:
            continue
        assert key in sdk, f"{key} missing from the SDK's {file}"
        assert sdk[key] == (item.address, item.size), key
        checked += 1
    assert checked >= 45


@pytest.mark.parametrize("number", sorted(COMPATIBLE_MODELS))
def test_compatible_models_have_every_driver_item_at_the_same_place(number):
    name, like = COMPATIBLE_MODELS[number]
    sdk = _sdk_model_file(name.lower().replace("-", "_") + ".model")
    table = model_by_name(like).table
    for item in DRIVER_ITEMS:
        assert sdk[item] == (table[item].address, table[item].size), (name, item)


def test_model_numbers_and_datasheet_facts():
    assert model_by_name("XM430-W350").number == 1020
    assert model_by_name("xl430_w250").number == 1060
    assert set(MODELS) == {1020, 1060}
    xm = model_by_name("XM430-W350")
    # 46 rpm at 12 V (hardware reference §5.3)
    assert xm.no_load_speed_rad_s_12v == pytest.approx(46 * 2 * math.pi / 60)
    assert "Present Current" in xm.table and "Present Load" not in xm.table
    assert "Present Load" in model_by_name("XL430-W250").table
    with pytest.raises(ValueError, match="supported models"):
        model_by_name("AX-12A")


def test_units_are_the_datasheet_units_in_si():
    t = model_by_name("XM430-W350").table
    assert t["Goal Velocity"].to_si(1) == pytest.approx(0.229 * 2 * math.pi / 60)
    assert t["Present Position"].to_si(4096) == pytest.approx(2 * math.pi)
    assert t["Profile Acceleration"].to_si(1) == pytest.approx(214.577 * 2 * math.pi / 3600)
    assert t["Present Input Voltage"].to_si(119) == pytest.approx(11.9)
    assert t["Bus Watchdog"].to_si(5) == pytest.approx(0.1)
    assert t["Return Delay Time"].to_si(250) == pytest.approx(500e-6)


def test_signed_items_decode_the_sdks_unsigned_values():
    t = model_by_name("XM430-W350").table
    pos = t["Present Position"]
    assert pos.decode(4294967291) == -5  # what read4ByteTxRx returns for -5 (§4.7)
    assert pos.from_bytes(bytes.fromhex("FF FF FD FF")) == -131073
    assert pos.to_bytes(-131073) == bytes.fromhex("FF FF FD FF")
    assert t["Velocity Limit"].decode(200) == 200
    assert t["Bus Watchdog"].decode(0xFF) == -1
    assert t["Goal Velocity"].from_si(1.0) == round(1.0 / (0.229 * 2 * math.pi / 60))
    with pytest.raises(ValueError, match="Goal Velocity"):
        t["Goal Velocity"].from_si(100.0)
    with pytest.raises(ValueError, match="finite"):
        t["Goal Position"].from_si(float("nan"))


def test_hardware_error_bits_follow_the_reference():
    assert {b.bit: b.name for b in HARDWARE_ERROR_BITS} == {
        0: "input voltage", 2: "overheating", 3: "motor encoder", 4: "electrical shock",
        5: "overload"}
    assert all(len(b.advice) > 40 for b in HARDWARE_ERROR_BITS)
