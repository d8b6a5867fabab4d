"""AR4000 driver against the emulator over a real pseudo-terminal."""

from __future__ import annotations

import pytest

from drivers.acuity import Ar4000Config, Ar4000Driver
from drivers.base import TARGETS_TAKEN, DeviceError
from hil_fixtures.ar4000 import Ar4000Emulator, source_from_table
from hil_fixtures.virtual_shovel import DriverRunner
from shoveld.installation import Installation
from shoveld.signals import SignalsTable

FAST = {"sample_interval_us": 10000, "command_gap_s": 0.005, "answer_timeout_s": 0.5,
        "silent_timeout_s": 0.3}


def driver_for(emu: Ar4000Emulator, **kw: object) -> Ar4000Driver:
    cfg = {"port": emu.port, **FAST, **kw}
    return Ar4000Driver("laser", Ar4000Config.from_config(cfg), backoff_s=(0.05, 0.2))


def distances(runner: DriverRunner) -> list[float]:
    return [r.values["distance_m"] for r in runner.readings if "distance_m" in r.values]


def test_configures_device_and_streams_distances() -> None:
    with Ar4000Emulator(lambda t: 4.321) as emu, DriverRunner(driver_for(emu)) as run:
        assert run.wait_for(lambda: len(distances(run)) >= 20, 5)
        # the commands the driver sent, as the emulator understood them
        assert emu.commands[:2] == ["A4", "S10000"]
        assert emu.output_mode == 4 and emu.sample_interval_us == 10000
        assert all(d == pytest.approx(4.321, abs=0.0005) for d in distances(run))
        assert run.driver.health.connected and run.driver.health.bad_frames == 0
        # readings arrive at the commanded 100 Hz (give or take scheduling)
        t = [r.t_host for r in run.readings[-15:]]
        assert (t[-1] - t[0]) / 14 == pytest.approx(0.01, rel=0.5)


def test_inch_output_and_optional_commands() -> None:
    with Ar4000Emulator(lambda t: 2.54) as emu, DriverRunner(driver_for(
            emu, units="in", max_range_m=16.51, min_amplitude=20, max_amplitude=1000)) as run:
        assert run.wait_for(lambda: len(distances(run)) >= 5, 5)
        assert emu.commands[:5] == ["A1", "S10000", "F650", "P20", "M1000"]
        assert distances(run)[-1] == pytest.approx(2.54, abs=0.0003)


def test_zero_means_no_target_and_is_never_a_distance() -> None:
    target = {"on": True}
    with Ar4000Emulator(lambda t: 3.0 if target["on"] else None) as emu, \
            DriverRunner(driver_for(emu, max_amplitude=1000)) as run:
        assert run.wait_for(lambda: len(distances(run)) >= 5, 5)
        target["on"] = False
        assert run.wait_for(lambda: run.driver.health.extra["no_target"] >= 5, 5)
        no_target = [r for r in run.readings if r.invalid]
        assert no_target and all(r.values == {} and r.invalid == {"distance_m"}
                                 for r in no_target)
        assert 0.0 not in distances(run)
        # amplitude above the commanded window (M1000) also reads zero -> invalid
        target["on"] = True
        emu.amplitude = 1010
        n = run.driver.health.extra["no_target"]
        assert run.wait_for(lambda: run.driver.health.extra["no_target"] >= n + 3, 5)


def test_silent_device_detected_then_recovered() -> None:
    with Ar4000Emulator(lambda t: 5.0) as emu, DriverRunner(driver_for(emu)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        emu.silent = True
        assert run.wait_for(lambda: h.timeouts >= 1 and not h.connected, 3)
        assert h.extra["silent"] and "silent" in (h.last_error or "")
        n = len(run.readings)
        emu.silent = False
        assert run.wait_for(lambda: h.connected and len(run.readings) > n + 5, 5)
        assert h.reconnects >= 1 and not h.extra["silent"]


def test_unplugged_then_plugged_back_reconnects_and_streams() -> None:
    """A pulled cable (the port vanishes, reads fail) is a disconnect that names the port;
    plugged back in, the driver opens it again and the device streams."""
    with Ar4000Emulator(lambda t: 5.0) as emu, DriverRunner(driver_for(emu)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        emu.unplug()
        assert run.wait_for(lambda: not h.connected and emu.port in (h.last_error or ""), 3), \
            h.last_error
        n = len(run.readings)
        emu.plug()
        assert run.wait_for(lambda: h.connected and len(run.readings) > n + 5, 5), \
            h.last_error
        assert h.reconnects >= 1 and distances(run)[-1] == pytest.approx(5.0, abs=0.01)


def test_babbling_counted_and_reported() -> None:
    with Ar4000Emulator(lambda t: 6.0) as emu, DriverRunner(driver_for(emu)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        emu.babble = 0.6
        assert run.wait_for(lambda: h.extra["babbling"], 5)
        assert h.bad_frames > 0 and h.rejected_bytes > h.bad_frames
        assert "babbling" in (h.last_error or "")
        # garbage never turned into a distance
        assert all(d == pytest.approx(6.0, abs=0.001) for d in distances(run))
        emu.babble = 0.0
        assert run.wait_for(lambda: not h.extra["babbling"], 5)


def test_something_else_in_the_beam_is_jumping_and_never_a_distance() -> None:
    """Returns from dust, a rope or the boom: well-formed lines 0.5-3 m off the handle.
    None is used, and health says the laser is jumping while they are a large share."""
    with Ar4000Emulator(lambda t: 4.321) as emu, DriverRunner(driver_for(emu)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(distances(run)) >= 5, 5)
        emu.stray = 0.5
        assert run.wait_for(lambda: h.extra["jumping"], 5)
        assert "jumping" in (h.last_error or "")
        assert h.extra["jumps"] >= 4  # more than 0.3 of at least 10 distances
        assert h.bad_frames == 0  # every line was well-formed
        n = len(distances(run))
        emu.stray = 0.0
        assert run.wait_for(lambda: not h.extra["jumping"] and len(distances(run)) > n + 20, 5)
        assert all(d == pytest.approx(4.321, abs=0.0005) for d in distances(run))


@pytest.mark.parametrize("other_target_s", [5.0, 0.3])
def test_something_that_stays_in_the_beam_is_refused_for_other_target_s(
        other_target_s: float) -> None:
    """Something in the beam 2.3 m in front of the handle for about a second: never a
    distance while it stays refused (5 s, the default); taken as the target once it has
    held for ``other_target_s`` when that is shorter, and then counted."""
    where = [4.321]
    with Ar4000Emulator(lambda t: where[0]) as emu, DriverRunner(
            driver_for(emu, other_target_s=other_target_s)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(distances(run)) >= 5, 5)
        n = len(run.readings)
        where[0] = 2.0
        assert run.wait_for(lambda: len(run.readings) >= n + 100, 5)  # 100 lines: 1 s
        where[0] = 4.321
        assert run.wait_for(lambda: distances(run)[-1] == pytest.approx(4.321, abs=5e-4), 15)
        assert h.extra["jumping"] or h.extra["jumps"] >= 45
        assert h.bad_frames == 0
        if other_target_s > 1.0:
            assert h.extra["other_target"] == 0
            assert all(d == pytest.approx(4.321, abs=5e-4) for d in distances(run))
        else:  # taken after 0.3 s: then the handle is what is refused, for as long
            assert h.extra["other_target"] == 2
            assert any(d == pytest.approx(2.0, abs=5e-4) for d in distances(run))


@pytest.mark.parametrize("after_m", [4.35, 0.5])
def test_a_reconnect_keeps_the_handles_reach(after_m: float) -> None:
    """The port goes silent (a cable, a power blip) and comes back. The handle, a few
    centimetres on, is used again at once; something 3.8 m in front of it, further than
    the handle can have moved in the gap, is refused for ``other_target_s`` and then
    counted as taken (the loop then marks the tick, and a pass across it is not
    weighed). Until the twenty-ninth session a reconnect forgot the last distance used,
    and the first two lines that agreed were taken, whatever they were, uncounted."""
    where = [4.321]
    with Ar4000Emulator(lambda t: where[0]) as emu, DriverRunner(
            driver_for(emu, other_target_s=0.5)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(distances(run)) >= 5, 5)
        emu.silent = True
        assert run.wait_for(lambda: not h.connected, 3)
        where[0] = after_m
        n = len(run.readings)
        emu.silent = False
        assert run.wait_for(lambda: h.connected and len(run.readings) > n + 100, 10)
        after = run.readings[n:]
        used = [r.values.get("distance_m") for r in after]
        assert h.reconnects >= 1
        if after_m > 1.0:  # the handle: in reach, used from the second line on
            assert all(d == pytest.approx(after_m, abs=5e-4) for d in used[1:])
            assert h.extra["other_target"] == 0
            assert all(TARGETS_TAKEN not in r.values for r in run.readings)
        else:  # refused for 0.5 s (50 lines at 100 Hz), then taken and counted
            first = next(i for i, d in enumerate(used) if d is not None)
            assert 45 <= first <= 60
            assert all(d == pytest.approx(after_m, abs=5e-4) for d in used[first:])
            assert h.extra["other_target"] == 1
            assert after[first].values[TARGETS_TAKEN] == 1.0


def test_only_garbage_is_treated_like_silence() -> None:
    with Ar4000Emulator(lambda t: 6.0) as emu, DriverRunner(driver_for(emu)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 3, 5)
        emu.babble = 1.0
        assert run.wait_for(lambda: h.timeouts >= 1, 5)
        assert "babbling" in (h.last_error or "") or "no answer" in (h.last_error or "")


def test_wrong_baud_rate_gives_a_clear_error() -> None:
    with Ar4000Emulator(lambda t: 1.0, baudrate=19200) as emu:
        drv = driver_for(emu, baudrate=9600)
        with pytest.raises(DeviceError) as e:
            drv.open()
        assert str(e.value) == (f"no answer from AR4000 on {emu.port} at 9600: "
                                "wrong baud rate or device off?")
        assert emu.commands == []  # the device could not understand a thing
        drv.close()
        drv.close()  # safe twice
        ok = driver_for(emu, baudrate=19200)
        ok.open()
        ok.close()


def test_missing_port_gives_clear_error() -> None:
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/nonexistent-ar4000"))
    with pytest.raises(DeviceError) as e:
        drv.open()
    assert str(e.value) == ("cannot open AR4000 port /dev/nonexistent-ar4000: No such file or "
                            "directory")


@pytest.mark.parametrize("cfg, key", [
    ({}, "port"),
    ({"port": "/dev/x", "baud": 9600}, "baud"),
    ({"port": "/dev/x", "baudrate": 1234}, "baudrate"),
    ({"port": "/dev/x", "baudrate": "9600"}, "baudrate"),
    ({"port": "/dev/x", "sample_interval_us": 10}, "sample_interval_us"),
    ({"port": "/dev/x", "units": "m"}, "units"),
    ({"port": "/dev/x", "max_range_m": -1.0}, "max_range_m"),
    ({"port": "/dev/x", "min_amplitude": 2000}, "min_amplitude"),
    ({"port": "/dev/x", "min_amplitude": 500, "max_amplitude": 100}, "min_amplitude"),
    ({"port": "/dev/x", "terminator": "X"}, "terminator"),
    ({"port": "/dev/x", "silent_timeout_s": 0}, "silent_timeout_s"),
])
def test_from_config_names_the_bad_key(cfg: dict[str, object], key: str) -> None:
    with pytest.raises(ValueError, match=f"'{key}'"):
        Ar4000Config.from_config(cfg)


def test_from_config_accepts_kind_and_builds_commands() -> None:
    cfg = Ar4000Config.from_config({"kind": "ar4000", "port": "/dev/x", "terminator": "\r\n"})
    assert cfg.commands() == [b"A4\r\n", b"S20000\r\n"]
    assert Ar4000Driver.from_config("l", {"port": "/dev/x"}).config.baudrate == 9600


def test_source_from_table_maps_crowd_through_installation() -> None:
    inst = Installation(crowd_offset_m=6.0, crowd_gain=1.0)
    table = SignalsTable.from_arrays(time_s=[10.0, 11.0, 12.0], crowd_m=[7.0, 8.0, float("nan")])
    src = source_from_table(table, inst)
    assert src(0.0) == pytest.approx(1.0)
    assert src(0.5) == pytest.approx(1.5)
    assert src(5.0) is None  # blank crowd -> no target


def test_emulator_follows_its_clock() -> None:
    now = {"t": 0.0}
    emu = Ar4000Emulator(lambda t: 1.0 + t, clock=lambda: now["t"])
    try:
        assert emu.format_sample(0.5) == b"59.06\r\n"  # inches by default (A1)
        emu._command("A4")
        assert emu.format_sample(0.5) == b"1500\r\n"
        emu.max_amplitude = 100
        assert emu.format_sample(0.5) == b"0\r\n"
    finally:
        emu.stop()
