"""Record emulated devices through the real drivers, replay through the same drivers."""

from __future__ import annotations

import json
import shutil
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.acuity import Ar4000Driver
from drivers.base import Driver, Reading
from drivers.capture import read_capture
from drivers.capture.recorder import RecordConfigError, Recorder, load_record_config
from drivers.capture.replay import (
    CanEndpoint,
    ModbusEndpoint,
    ReplaySession,
    SerialEndpoint,
    open_replay,
)
from drivers.modbus_adc import ChannelMap, ModbusAdcDriver
from hil_fixtures.ar4000 import Ar4000Emulator
from hil_fixtures.modbus_adc import ModbusAdcEmulator
from hil_fixtures.virtual_shovel import INCLINOMETER_CHANNELS, MOTOR_CHANNELS, DriverRunner
from shoveld.installation import Installation
from shoveld.signals import SignalsTable

from .conftest import answered, t_device

CAPTURES = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures"

CHANNELS = ChannelMap.from_config([
    {"name": "hoist1_a", "register": 0, "scale": 400.0},
    {"name": "roll_deg", "register": 1, "scale": 3.0},
])


def laser_cfg(port: str) -> dict[str, Any]:
    return {"kind": "ar4000", "port": port, "sample_interval_us": 10000,
            "command_gap_s": 0.005, "answer_timeout_s": 1.0, "silent_timeout_s": 0.3}


def replay_through(session: ReplaySession, make: dict[str, Callable[[dict[str, Any]], Driver]],
                   tick: float = 0.01) -> dict[str, list[Reading]]:
    """Run one driver per device against the session until everything is replayed."""
    runners = {n: DriverRunner(f(session.driver_config(n))).start() for n, f in make.items()}
    try:
        assert session.wait_connected([r.driver for r in runners.values()])
        end = time.monotonic() + 20
        while not session.finished and time.monotonic() < end:
            if session.clock.stepped:
                session.clock.advance(tick)
            else:
                time.sleep(0.02)
        time.sleep(0.05)
    finally:
        for r in runners.values():
            r.stop()
    return {n: r.readings for n, r in runners.items()}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """1.5 s of a moving laser and an ADC whose module goes quiet for a while."""
    out = tmp_path_factory.mktemp("cap") / "c1"
    with Ar4000Emulator(lambda t: 3.0 + 0.5 * t if not 0.6 < t < 0.7 else None) as laser, \
            ModbusAdcEmulator(lambda t: {"hoist1_a": 1000.0 * t, "roll_deg": 2.0}, CHANNELS,
                              transport="rtu") as adc:
        cfg = {"installation": {"crowd_offset_m": 6.0},
               "devices": {"laser": laser_cfg(laser.port),
                           "adc": adc.driver_config(poll_hz=50, timeout_s=0.05)}}
        rec = Recorder(cfg, out)
        rec.start()
        time.sleep(1.0)
        adc.silent = True
        time.sleep(0.2)
        adc.silent = False
        time.sleep(0.3)
        summary = rec.stop()
    return out, summary


def test_recording_holds_the_raw_stream(recorded: tuple[Path, dict[str, Any]]) -> None:
    out, summary = recorded
    assert summary["laser"]["readings"] > 100 and summary["adc"]["readings"] > 50
    cap = read_capture(out)
    assert cap.installation == {**cap.installation, "crowd_offset_m": 6.0}
    assert cap.devices["adc"].kind == "modbus_rtu"
    chunks = list(cap.serial_chunks("laser"))
    tx = b"".join(c.data for c in chunks if c.direction == "tx")
    assert tx == b"A4\rS10000\r"
    rx = b"".join(c.data for c in chunks if c.direction == "rx")
    assert rx.count(b"\r\n") > 100 and b"\r\n0\r\n" in rx  # zero = no target recorded raw
    reads = list(cap.modbus_reads("adc"))
    assert sum(r.error == "timeout" for r in reads) >= 2
    assert 1.3 < cap.duration_s() < 3.0


@pytest.mark.parametrize("speed", [1.5, None], ids=["paced-x1.5", "stepped"])
def test_replay_through_the_same_drivers(recorded: tuple[Path, dict[str, Any]],
                                         speed: float | None) -> None:
    out, _ = recorded
    cap = read_capture(out)
    rx = b"".join(c.data for c in cap.serial_chunks("laser") if c.direction == "rx")
    recorded_reads = [r for r in cap.modbus_reads("adc")]
    with open_replay(out, speed=speed) as s:
        ep = s.endpoints["laser"]
        assert isinstance(ep, SerialEndpoint)
        assert Path(ep.port).exists()  # a real tty the driver opens
        got = replay_through(s, {
            "laser": lambda c: Ar4000Driver.from_config("laser", c, clock=s.clock),
            "adc": lambda c: ModbusAdcDriver.from_config("adc", c, clock=s.clock)})
        assert s.clock.unsettled_steps == 0
    laser = got["laser"]
    dist = [r.values["distance_m"] for r in laser if r.values]
    # the replayed distances are the recorded ones, in order (the first few may be
    # lost while the driver connects; the first after the no-target stretch, 0.1 s
    # and so longer than the 5 samples a last distance used is followed from, has
    # nothing to follow from and is not used)
    lines = [int(x) for x in rx.split(b"\r\n") if x.strip()]
    want = [v * 0.001 for i, v in enumerate(lines) if v != 0 and i and lines[i - 1] != 0]
    # paced replay streams on while a driver connects (as live): its start may be lost
    keep = 0.6 if speed else 0.8
    assert len(dist) > keep * len(want)
    k = want.index(dist[0])
    assert dist == want[k:k + len(dist)]
    assert any(r.invalid == {"distance_m"} for r in laser)
    # readings carry capture time, monotonically
    ts = [r.t_host for r in laser]
    assert ts == sorted(ts) and 0 <= ts[0] and ts[-1] <= cap.duration_s() + 0.1
    adc = got["adc"]
    assert len(adc) > keep * len(recorded_reads)
    ok = [r for r in adc if r.values]
    dead = [r for r in adc if not r.values]
    assert dead and all(r.invalid == {"hoist1_a", "roll_deg"} for r in dead)
    recorded_hoist = {round(CHANNELS.decode(0, r.registers)["hoist1_a"], 3)
                      for r in recorded_reads if r.registers}
    assert {round(r.values["hoist1_a"], 3) for r in ok} <= recorded_hoist
    # the recorded silence happens at the same capture time in the replay (before the
    # first recorded read the replay answers "busy": invalid too, never invented). The
    # dead reading nearest it, not the first: an answer later than the driver's 50 ms
    # timeout on a loaded machine is a timeout, as live (a paced replay on two busy
    # cores: one at 0.242 s after a 90 ms gap in the readings, the silence at 1.068 s)
    first_ok = min(r.t_host for r in ok)
    dead_t = [r.t_host for r in dead if r.t_host > first_ok]
    silence_t = min(r.t for r in recorded_reads if r.error == "timeout")
    assert min(abs(t - silence_t) for t in dead_t) < 0.15


def test_modbus_tcp_replay_serves_on_a_free_local_port(tmp_path: Path) -> None:
    out = tmp_path / "c"
    with ModbusAdcEmulator(lambda t: {"hoist1_a": 500.0, "roll_deg": -1.0}, CHANNELS) as adc:
        Recorder({"devices": {"adc": adc.driver_config(poll_hz=100)}}, out).run(0.3)
    with open_replay(out, speed=None) as s:
        ep = s.endpoints["adc"]
        assert isinstance(ep, ModbusEndpoint)
        assert ep.host == "127.0.0.1" and ep.port and ep.port != adc.port
        got = replay_through(s, {"adc": lambda c: ModbusAdcDriver.from_config(
            "adc", c, clock=s.clock)})
    vals = [r.values for r in got["adc"] if r.values]
    assert len(vals) > 15
    assert all(v["hoist1_a"] == pytest.approx(500.0, abs=0.2) for v in vals)


def test_mti_serial_handshake_is_answered_from_the_recording(tmp_path: Path) -> None:
    mti = pytest.importorskip("hil_fixtures.mti")
    from drivers.xsens.serial_driver import MtiSerialDriver

    out = tmp_path / "c"
    with mti.MtiEmulator(lambda t: (0.0, 10.0 + t, 20.0)) as emu:
        cfg = {"devices": {"mti": {"kind": "mti_serial", "port": emu.port,
                                   "baudrate": 115200, "rate_hz": 100}}}
        recorded = Recorder(cfg, out).run(1.0)["mti"]["readings"]
    assert recorded > 30
    for speed in (1.0, None):
        with open_replay(out, speed=speed) as s:
            got = replay_through(s, {"mti": lambda c: MtiSerialDriver.from_config(
                {k: v for k, v in c.items() if k != "kind"}, clock=s.clock)})
        r = got["mti"]
        # paced replay streams while the driver does its handshake: the start may be lost
        assert len(r) > (0.4 if speed else 0.8) * recorded, speed
        assert r[-1].values["pitch_deg"] == pytest.approx(10.0 + t_device(r[-1]), abs=0.02)


def test_an_mti_capture_from_before_the_quaternion_replays_as_recorded(tmp_path: Path) -> None:
    """Captures name the MTi's orientation and extra outputs; one that does not was
    recorded when the driver asked for Euler angles alone, with the rate of turn, the
    acceleration and the status word, and must be configured so on replay (the default
    now asks for the quaternion and none of the three, which such a recording never
    acknowledged)."""
    mti = pytest.importorskip("hil_fixtures.mti")
    from drivers.xsens.serial_driver import EXTRA_OUTPUTS, MtiSerialDriver

    out = tmp_path / "c"
    with mti.MtiEmulator(lambda t: (0.0, 10.0 + t, 20.0)) as emu:
        cfg = {"devices": {"mti": {"kind": "mti_serial", "port": emu.port,
                                   "orientation": "euler",
                                   "extra_outputs": list(EXTRA_OUTPUTS)}}}
        Recorder(cfg, out).run(0.6)
    with mti.MtiEmulator(lambda t: (0.0, 10.0 + t, 20.0)) as emu:
        Recorder({"devices": {"mti": {"kind": "mti_serial", "port": emu.port}}},
                 tmp_path / "new").run(0.3)
    new = read_capture(tmp_path / "new").devices["mti"].settings["config"]
    # recorded even though they are the defaults
    assert (new["orientation"], new["extra_outputs"]) == ("euler+quaternion", [])
    mpath = out / "manifest.json"
    m = json.loads(mpath.read_text())
    del m["devices"]["mti"]["config"]["orientation"]
    del m["devices"]["mti"]["config"]["extra_outputs"]
    mpath.write_text(json.dumps(m))
    old = read_capture(out).devices["mti"].settings["config"]
    assert (old["orientation"], old["extra_outputs"]) == ("euler", list(EXTRA_OUTPUTS))
    with open_replay(out, speed=None) as s:
        got = replay_through(s, {"mti": lambda c: MtiSerialDriver.from_config(
            {k: v for k, v in c.items() if k != "kind"}, clock=s.clock)})
    assert len(got["mti"]) > 20
    assert all("gyr_z" in r.values and "status_word" in r.values for r in got["mti"])


def test_can_replay_through_python_can_virtual_bus(tmp_path: Path) -> None:
    mti_can = pytest.importorskip("hil_fixtures.mti_can")
    from drivers.xsens.can_driver import MtiCanDriver

    out = tmp_path / "c"
    channel = f"test-{uuid.uuid4().hex[:8]}"
    with mti_can.MtiCanEmulator(lambda t: (0.0, 5.0, 20.0), channel):
        cfg = {"devices": {"mti": {"kind": "mti_can", "interface": "virtual",
                                   "channel": channel}}}
        Recorder(cfg, out).run(0.5)
    with open_replay(out, speed=None) as s:
        ep = s.endpoints["mti"]
        assert isinstance(ep, CanEndpoint) and ep.channel != channel
        got = replay_through(s, {"mti": lambda c: MtiCanDriver.from_config(
            {k: v for k, v in c.items() if k != "kind"}, clock=s.clock)})
    assert len(got["mti"]) > 30
    assert got["mti"][-1].values["pitch_deg"] == pytest.approx(5.0, abs=0.01)


def test_shoveld_record_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import main

    with Ar4000Emulator(lambda t: 2.0) as laser:
        cfg = tmp_path / "rec.toml"
        cfg.write_text(f'[installation]\ncrowd_offset_m = 5.5\n\n[devices.laser]\n'
                       f'kind = "ar4000"\nport = "{laser.port}"\nsample_interval_us = 10000\n'
                       'command_gap_s = 0.005\n')
        assert main(["record", "--config", str(cfg), "--out", str(tmp_path / "o"),
                     "--duration", "0.4"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["devices"]["laser"]["readings"] > 10
    cap = read_capture(tmp_path / "o")
    assert cap.installation["crowd_offset_m"] == 5.5
    assert main(["record", "--config", str(cfg), "--out", str(tmp_path / "o"),
                 "--duration", "0.1"]) == 2  # refuses to overwrite
    assert "not empty" in capsys.readouterr().err


@pytest.mark.parametrize("text, msg", [
    ("[devices.x]\nkind = 'laser'\n", "[devices.x] key 'kind' must be one of"),
    ("devices = 1\n", "needs at least one [devices.<name>]"),
    ("[devices.x]\nkind = 'ar4000'\n[installation]\ncrowd_gain = 'a'\n", "'crowd_gain'"),
    ("[devices.x\n", "not valid TOML"),
])
def test_record_config_errors(tmp_path: Path, text: str, msg: str) -> None:
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(RecordConfigError) as e:
        load_record_config(p)
    assert str(e.value).startswith(str(p)) and msg in str(e.value)
    with pytest.raises(RecordConfigError, match=r"\[devices.l\]: ar4000: unknown key 'speed'"):
        Recorder({"devices": {"l": {"kind": "ar4000", "port": "/dev/x", "speed": 1}}},
                 tmp_path / "o")


@pytest.mark.parametrize("device", [
    {"kind": "ar4000"},  # no port
    {"kind": "mti_serial", "port": "/dev/x", "baudrate": "fast"},
    {"kind": "mti_can", "interface": "virtual"},  # no channel
    {"kind": "modbus_tcp", "host": "127.0.0.1", "channels": 7},
])
def test_a_refused_device_leaves_the_output_as_it_was(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], device: dict[str, Any]) -> None:
    """The devices' keys are checked before the capture is opened: a refused one makes no
    empty capture, and an ``--overwrite`` of an old capture does not replace its manifest
    with one of no device (it did, 2026-11-30: the old capture could no longer be
    replayed). The laser comes first, so its file would be the first written."""
    from shoveld.cli import main

    good = {"kind": "ar4000", "port": "/dev/x"}
    cfg = tmp_path / "rec.toml"
    cfg.write_text("".join(
        f"[devices.{n}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in d.items())
        for n, d in (("laser", good), ("bad", device))))
    new = tmp_path / "new" / "capture"
    assert main(["record", "--config", str(cfg), "--out", str(new), "--duration", "0.1"]) == 2
    assert "[devices.bad]" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    old = tmp_path / "old"
    shutil.copytree(CAPTURES / "daemon-e2e", old)
    before = {p.name: p.read_bytes() for p in old.iterdir()}
    assert main(["record", "--config", str(cfg), "--out", str(old), "--overwrite",
                 "--duration", "0.1"]) == 2
    assert "[devices.bad]" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in old.iterdir()} == before


def test_make_capture_from_a_signals_table(tmp_path: Path) -> None:
    """Simulated shovel -> emulators -> real drivers -> capture -> replay -> same signals."""
    from hil_fixtures.make_capture import make_capture

    t = np.arange(0.0, 4.0, 0.02)
    table = SignalsTable.from_arrays(
        time_s=t + 100.0, handle_deg=10 + 5 * np.sin(t), crowd_m=8 + np.sin(t),
        swing_deg=20 * np.sin(t / 2), boom_deg=np.full_like(t, 45.0),
        hoist1_a=1500 + 500 * np.sin(t), hoist2_a=1500 + 500 * np.sin(t),
        hoist_field_a=np.full_like(t, 80.0), crowd_a=300 * np.cos(t),
        crowd_field_a=np.full_like(t, 50.0), swing_a=800 * np.sin(t / 2),
        swing_field_a=np.full_like(t, 60.0), roll_deg=np.full_like(t, 1.0),
        pitch_deg=np.full_like(t, -2.0))
    inst = Installation(crowd_offset_m=6.0)
    summary = make_capture(table, tmp_path / "c", speed=2.0, mti="serial", installation=inst)
    assert all(d["readings"] > 50 for d in summary["devices"].values())
    cap = read_capture(tmp_path / "c")
    assert cap.manifest["signals_table"]["t0_s"] == 100.0
    assert set(cap.devices) == {"laser", "mti", "adc_motors", "adc_incl"}
    # the capture holds what the table says (host receive times lag the device a little;
    # on a loaded machine the paced clock amplifies scheduling delays by the speed)
    buf, err = b"", []
    for c in cap.serial_chunks("laser"):
        if c.direction == "rx":
            buf += c.data
            *lines, buf = buf.split(b"\r\n")
            err += [abs(inst.crowd_m(int(x) * 0.001) - np.interp(c.t + 100.0, table.time,
                                                                table["crowd_m"]))
                    for x in lines if x.strip() and int(x)]
    assert len(err) > 100 and np.median(err) < 0.01 and np.percentile(err, 75) < 0.05
    reads = [r for r in cap.modbus_reads("adc_motors") if r.registers]
    hoist = np.array([MOTOR_CHANNELS.decode(0, answered(r))["hoist1_a"] for r in reads])
    want_h = np.interp([r.t + 100.0 for r in reads], table.time, table["hoist1_a"])
    assert len(reads) > 100 and np.median(np.abs(hoist - want_h)) < 10.0
    # and replays through the same drivers as recorded
    with open_replay(tmp_path / "c", speed=None, devices=["laser", "adc_motors"]) as s:
        assert set(s.endpoints) == {"laser", "adc_motors"}
        got = replay_through(s, {
            "laser": lambda c: Ar4000Driver.from_config("laser", c, clock=s.clock),
            "adc_motors": lambda c: ModbusAdcDriver.from_config("m", c, clock=s.clock)})
    assert len(got["laser"]) > 0.9 * len(err)
    got_h = {round(r.values["hoist1_a"], 6) for r in got["adc_motors"] if r.values}
    assert len(got_h) > 50 and got_h <= {round(h, 6) for h in hoist}


def test_virtual_shovel_with_can_mti_and_rtu_modules(tmp_path: Path) -> None:
    """Every emulator from one table on one clock; the recorder's drivers read them all."""
    pytest.importorskip("hil_fixtures.mti_can")
    from drivers.capture.clock import ReplayClock
    from hil_fixtures.virtual_shovel import VirtualShovel

    t = np.arange(0.0, 3.0, 0.02)
    table = SignalsTable.from_arrays(
        time_s=t, handle_deg=np.full_like(t, 12.0), crowd_m=np.full_like(t, 8.0),
        swing_deg=np.full_like(t, 30.0), boom_deg=np.full_like(t, 45.0),
        hoist1_a=np.full_like(t, 2000.0), roll_deg=np.full_like(t, 1.5))
    clock = ReplayClock(0.0, speed=2.0)
    with VirtualShovel(table, clock=clock, mti="can", adc_transport="rtu") as vs:
        cfg = vs.config()
        assert cfg["devices"]["adc_motors"]["kind"] == "modbus_rtu"
        summary = Recorder(cfg, tmp_path / "c", clock=clock).run(1.5)
    assert all(d["readings"] > 20 for d in summary.values()), summary
    cap = read_capture(tmp_path / "c")
    assert any(m.arbitration_id == 0x22 for _, m in cap.can_messages("mti"))  # EulerAngles
    reads = [r for r in cap.modbus_reads("adc_motors") if r.registers]
    assert MOTOR_CHANNELS.decode(0, answered(reads[-1]))["hoist1_a"] == pytest.approx(
        2000.0, abs=0.2)
    incl = [r for r in cap.modbus_reads("adc_incl") if r.registers]
    assert INCLINOMETER_CHANNELS.decode(0, answered(incl[-1]))["roll_deg"] == pytest.approx(
        1.5, abs=0.01)


def test_a_capture_torn_by_a_power_cut_replays_up_to_the_tear(tmp_path: Path) -> None:
    """The recorder's last line, cut off mid-write, is not an error: the replay plays what
    is there and says where it stopped."""
    import shutil
    import subprocess
    import sys

    src = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
    cap = tmp_path / "cap"
    shutil.copytree(src, cap)
    for name in ("laser.serial.jsonl", "adc_motors.modbus.jsonl"):
        f = cap / name
        data = f.read_bytes()
        f.write_bytes(data[:-25])  # the last record loses its end and its newline
        lines = data[:-25].count(b"\n") + 1
    r = subprocess.run([sys.executable, "-m", "shoveld", "replay", str(cap), "--fast",
                        "--state-dir", str(tmp_path / "state")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "adc_motors.modbus.jsonl:" in r.stderr and "cut off" in r.stderr
    assert f"up to line {lines - 1}" in r.stderr
    # a bad line that is not the last is still an error naming it
    f = cap / "laser.serial.jsonl"
    text = f.read_text().splitlines(keepends=True)
    text[3] = "{not json\n"
    f.write_text("".join(text))
    r = subprocess.run([sys.executable, "-m", "shoveld", "replay", str(cap), "--fast",
                        "--state-dir", str(tmp_path / "state2")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and "laser.serial.jsonl:4" in r.stderr
    assert "Traceback" not in r.stderr


def test_a_record_python_cannot_hold_is_a_format_error(tmp_path: Path) -> None:
    from drivers.capture.format import CaptureFormatError, read_serial_chunks

    src = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
    lines = (src / "laser.serial.jsonl").read_text().splitlines(keepends=True)
    f = tmp_path / "laser.serial.jsonl"
    f.write_text(lines[0] + '{"t": ' + "9" * 5000 + ', "d": "rx", "hex": ""}\n')
    with pytest.raises(CaptureFormatError, match=r"laser.serial.jsonl:2: not valid JSON"):
        list(read_serial_chunks(f))
