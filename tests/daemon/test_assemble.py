"""Readings -> Sample: installation maps, alignment, and invalid rather than made-up numbers."""

from __future__ import annotations

import math

import pytest

from drivers.base import TARGETS_TAKEN, DriverHealth, Reading
from shoveld.daemon.assemble import Assembler
from shoveld.daemon.store import ReadingStore
from shoveld.installation import Installation
from shoveld.replay.table import table_devices
from shoveld.sample import CROWD_TARGET_CHANGED

INST = Installation(handle_pitch_offset_deg=2.0, handle_pitch_sign=-1.0,
                    swing_yaw_zero_deg=170.0, crowd_offset_m=6.0, crowd_gain=1.1)


def setup(health: dict[str, DriverHealth] | None = None,
          max_age: float = 0.1) -> tuple[ReadingStore, Assembler]:
    devs = table_devices(max_age)
    store = ReadingStore(devs)
    health = health or {n: DriverHealth(connected=True) for n in devs}
    return store, Assembler(devs, INST, store, health.get)


MOTORS = {"hoist1_a": 1000.0, "hoist2_a": 990.0, "hoist_field_a": 70.0, "crowd_a": -200.0,
          "crowd_field_a": 30.0, "swing_a": 5.0, "swing_field_a": 30.0}


def feed_all(store: ReadingStore, t: float, yaw: float = 175.0, pitch: float = 10.0) -> None:
    store.put("mti", Reading("mti", t, {"pitch_deg": pitch, "yaw_deg": yaw, "roll_deg": 0.5}))
    store.put("laser", Reading("laser", t, {"distance_m": 2.0}))
    store.put("adc_motors", Reading("adc_motors", t, dict(MOTORS)))
    store.put("adc_incl", Reading("adc_incl", t, {"boom_deg": 45.0, "roll_deg": 1.0,
                                                  "pitch_deg": -0.5}))


def test_joint_variables_through_the_installation() -> None:
    store, asm = setup()
    feed_all(store, 1.0)
    s = asm.sample(1.0)
    assert s.invalid == frozenset()
    assert s.handle_deg == pytest.approx(-10.0 + 2.0)
    assert s.swing_deg == pytest.approx(5.0)
    assert s.crowd_m == pytest.approx(6.0 + 1.1 * 2.0)
    assert s.hoist1_a == 1000.0 and s.crowd_a == -200.0 and s.boom_deg == 45.0
    # the house inclinometers are the ADC's roll/pitch, never the MTi's
    assert s.roll_deg == 1.0 and s.pitch_deg == -0.5
    assert asm.state["mti"].state == "ok"


def test_swing_is_unwrapped_through_180() -> None:
    store, asm = setup()
    swings = []
    for i, yaw in enumerate([0.0, 120.0, -120.0, -10.0, 100.0, -140.0]):
        feed_all(store, 0.01 * i, yaw=170.0 + yaw)
        swings.append(asm.sample(0.01 * i).swing_deg)
    assert swings == pytest.approx([0.0, 120.0, 240.0, 350.0, 460.0, 580.0])


def test_reading_after_the_tick_is_interpolated() -> None:
    store, asm = setup()
    feed_all(store, 1.00, pitch=10.0, yaw=170.0)
    feed_all(store, 1.02, pitch=12.0, yaw=172.0)
    s = asm.sample(1.01)
    assert s.handle_deg == pytest.approx(2.0 - 11.0)
    assert s.swing_deg == pytest.approx(1.0)
    assert asm.state["mti"].age_s == 0.0
    # yaw across the wrap: short way round
    store2, asm2 = setup()
    feed_all(store2, 1.00, yaw=179.0)
    feed_all(store2, 1.02, yaw=-179.0)
    assert asm2.sample(1.01).swing_deg == pytest.approx(10.0, abs=1e-9)


def test_stale_device_makes_its_signals_invalid() -> None:
    store, asm = setup(max_age=0.1)
    feed_all(store, 1.0)
    store.put("mti", Reading("mti", 1.25, {"pitch_deg": 10.0, "yaw_deg": 170.0}))
    s = asm.sample(1.25)
    assert {"crowd_m", "hoist1_a", "boom_deg"} <= s.invalid
    assert "handle_deg" not in s.invalid
    assert math.isnan(s.crowd_m) and math.isnan(s.hoist1_a)
    assert asm.state["laser"].state == "stale"
    assert asm.state["laser"].age_s == pytest.approx(0.25)


def test_disconnected_driver_and_no_data() -> None:
    health = {n: DriverHealth(connected=True) for n in table_devices()}
    store, asm = setup(health)
    s = asm.sample(0.0)
    assert {"handle_deg", "crowd_m", "hoist1_a"} <= s.invalid
    assert asm.state["mti"].state == "no_data"
    feed_all(store, 1.0)
    health["adc_motors"].connected = False
    s = asm.sample(1.0)
    assert set(MOTORS) <= s.invalid and "crowd_m" not in s.invalid
    assert asm.state["adc_motors"].state == "disconnected"


def test_reported_invalid_and_implausible_values() -> None:
    store, asm = setup()
    feed_all(store, 1.0)
    store.put("laser", Reading("laser", 1.0, {}, frozenset({"distance_m"})))  # no target
    store.put("adc_motors", Reading("adc_motors", 1.0, {**MOTORS, "hoist2_a": 90000.0},
                                    frozenset({"crowd_a"})))
    s = asm.sample(1.0)
    assert {"crowd_m", "crowd_a", "hoist2_a"} <= s.invalid
    assert math.isnan(s.crowd_m) and math.isnan(s.hoist2_a)
    assert s.hoist1_a == 1000.0
    assert asm.state["laser"].state == "invalid"
    assert asm.state["adc_motors"].invalid == ["crowd_a", "hoist2_a"]


def test_a_change_of_laser_target_marks_one_tick() -> None:
    """The tick that first uses a reading whose count of targets taken has grown is
    marked, once: not again while that reading is held, nor when a distance carries the
    same count after a no-target line, nor where a reading it missed between two ticks
    had the new count first."""
    store, asm = setup()
    marks = []

    def tick(t: float, laser: Reading | None) -> None:
        feed_all(store, t)
        if laser is not None:
            store.put("laser", laser)
        marks.append(CROWD_TARGET_CHANGED in asm.sample(t).invalid)

    tick(1.00, None)
    tick(1.01, Reading("laser", 1.01, {"distance_m": 2.5, TARGETS_TAKEN: 1.0}))
    store.put("mti", Reading("mti", 1.02, {"pitch_deg": 10.0, "yaw_deg": 175.0}))
    marks.append(CROWD_TARGET_CHANGED in asm.sample(1.02).invalid)  # the same laser reading
    tick(1.03, Reading("laser", 1.03, {}, frozenset({"distance_m"})))  # no target
    tick(1.04, Reading("laser", 1.04, {"distance_m": 2.5, TARGETS_TAKEN: 1.0}))
    store.put("laser", Reading("laser", 1.045, {"distance_m": 2.0, TARGETS_TAKEN: 2.0}))
    tick(1.05, Reading("laser", 1.05, {"distance_m": 2.0, TARGETS_TAKEN: 2.0}))
    tick(1.06, Reading("laser", 1.06, {"distance_m": 2.0, TARGETS_TAKEN: 2.0}))
    assert marks == [False, True, False, False, False, True, False]


def test_new_arrivals_are_reported_once() -> None:
    store, asm = setup()
    feed_all(store, 1.0)
    asm.sample(1.0)
    assert len(asm.new_arrivals) == 4
    asm.sample(1.01)
    assert asm.new_arrivals == []
    assert store.count("mti") == 1
