"""The whole daemon fed from a capture, through the drivers and their virtual hardware.

:func:`replay_service` opens the capture with the drivers' replay (ptys, a virtual
CAN bus, a local Modbus server answering from the recording), points each device's
recorded driver configuration at its replay endpoint, and builds a normal
:class:`Service` on a replay clock: stepped (as fast as the machine allows,
deterministic) or paced at ``speed`` times the recorded pace. Everything after the
drivers - store, assembly, engine, pass log, Zenoh - is the live code.
:func:`fast_replay_service` runs the drivers on in-memory transports instead, fed to
the same service in bulk (or tick by tick).
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import logging
import math
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shoveld.daemon.clock import ReplayPacedClock, ReplayStepClock, SimClock
from shoveld.daemon.config import DaemonConfig, DeviceConfig, device_signals
from shoveld.daemon.publisher import Publisher
from shoveld.daemon.service import Service
from shoveld.installation import Installation
from shoveld.model.params import ModelParams
from shoveld.replay.sync import SyncReplay

log = logging.getLogger(__name__)


@dataclass
class ReplayRun:
    """A service wired to a replay session; ``run()`` plays it to the end."""

    service: Service
    session: Any
    speed: float | None

    def run(self, stop: threading.Event | None = None, connect_timeout_s: float = 15.0,
            until_s: float | None = None) -> dict[str, Any]:
        """Wait for the drivers, play the capture, close the last truck; return figures."""
        stop = stop or threading.Event()
        svc = self.service
        paced = self.speed is not None and svc.driver_threads
        recording = getattr(self.session, "clock", None)
        # it starts now (replay_service held it)
        if recording is not None and getattr(recording, "held", False):
            recording.restart()
        if self.speed is None and svc.driver_threads and hasattr(self.session,
                                                                  "wait_connected"):
            # stepped: the replay moves time at about real pace while drivers connect
            self.session.wait_connected(list(svc.drivers.values()), connect_timeout_s)
        elif paced and not svc.wait_drivers(connect_timeout_s):
            # paced: give the drivers their handshakes before the recording runs away.
            # Stepped: time stands still until the loop moves it, and some devices only
            # count as connected once data flows, so the loop starts at once.
            down = [n for n, d in svc.drivers.items() if not d.health.connected]
            log.warning("replay: drivers %s not connected after %.0f s; playing anyway", down,
                        connect_timeout_s)
        limit = getattr(self.session, "limit", None)
        if limit is not None:  # a feed that works ahead of the ticks must know where to stop
            limit(until_s)
        t_cpu, t_real = time.process_time(), time.monotonic()
        t0 = svc.clock.now()
        clock = svc.clock

        session = self.session
        end = math.inf if until_s is None else until_s

        def done_at() -> bool:
            return bool(session.finished or clock.now() >= end)

        def done_at_end() -> bool:  # asked at every tick: no clock to read without --until
            return bool(session.finished)
        done = done_at_end if until_s is None else done_at
        if not svc.driver_threads:
            # what is alive now (the service, the engine, the pass log, Zenoh's objects)
            # lives to the end: set aside from the collector, as the capture's objects
            # are (gc_paused), so that its collections during the play walk only what the
            # play makes (2-3 ms of a 0.17 s replay; ReplayRun.close unfreezes)
            gc.freeze()
        svc.run(stop, done=done)
        error = getattr(self.session, "error", None)
        if error is not None:  # the bulk feed failed: the ticks after it had no samples
            raise error
        real = time.monotonic() - t_real
        played = svc.clock.now() - t0
        return {"capture_s": round(played, 3), "real_s": round(real, 3),
                "speed_x": round(played / real, 1) if real > 0 else None,
                "cpu_s": round(time.process_time() - t_cpu, 3),
                "ticks": svc.loop_stats.ticks,
                "unsettled_steps": getattr(self.session.clock, "unsettled_steps", 0)}

    def close(self) -> None:
        try:
            self.service.close()
        finally:
            self.session.close()
            gc.unfreeze()  # (see gc_paused: the collector looks at everything again)


def replay_devices(session: Any, max_age_s: float) -> dict[str, DeviceConfig]:
    """DeviceConfigs of the recorded devices, re-pointed at their replay endpoints."""
    out = {}
    for name in session.endpoints:
        d = session.driver_config(name)
        kind = d["kind"]
        out[name] = DeviceConfig(name, kind, d, max_age_s, device_signals(kind, d))
    return out


def _installation(cap: Any, default: Installation) -> Installation:
    if not cap.installation:
        return default
    known = {f.name for f in dataclasses.fields(Installation)}
    return Installation(**{k: float(v) for k, v in cap.installation.items() if k in known})


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """No cyclic garbage collection inside, and what is alive at the end set aside from
    it (``gc.freeze``) until :meth:`ReplayRun.close`: reading a capture makes a few
    hundred thousand objects that all live until the replay ends. The collector's passes
    over them while they were made were 25-50 ms of the command, and left young, they
    would be walked again by the first collections of the replay itself."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.freeze()
        if was:
            gc.enable()


def fast_replay_service(capture_dir: str | Path, cfg: DaemonConfig, params: ModelParams, *,
                        record_stats: bool = False, close_truck_at_end: bool = True,
                        bulk: bool = True) -> ReplayRun:
    """The service on the drivers' in-memory transports: deterministic, as fast as the
    engine allows. ``bulk``: each device decoded alone and the samples built with numpy
    ahead of the ticks (:mod:`shoveld.replay.bulk`); else the drivers, the store
    and the assembler run inside each tick (:class:`SyncReplay`), as live. Both give the
    same samples and passes (tests/replay/test_bulk.py).

    The Zenoh session starts opening first, in its thread, while the capture is read
    (``Service.start`` then waits for it as usual): opening it is 5 ms that release the
    GIL, which the command no longer waits for after the reading."""
    publisher = Publisher(cfg.zenoh, cfg.shovel_id).start()
    try:
        return _fast_replay_service(capture_dir, cfg, params, publisher, record_stats,
                                    close_truck_at_end, bulk)
    except BaseException:
        publisher.close()
        raise


def _fast_replay_service(capture_dir: str | Path, cfg: DaemonConfig, params: ModelParams,
                         publisher: Publisher, record_stats: bool, close_truck_at_end: bool,
                         bulk: bool) -> ReplayRun:
    from drivers.capture.format import read_capture

    cap = read_capture(Path(capture_dir))
    devices = {}
    for name, dev in cap.devices.items():
        d = dict(dev.settings.get("config") or {})
        d["kind"] = dev.kind
        devices[name] = DeviceConfig(name, dev.kind, d, cfg.loop.max_age_s,
                                     device_signals(dev.kind, d))
    with gc_paused():
        sync = SyncReplay(cap, devices)
    rcfg = dataclasses.replace(cfg, devices=devices,
                               installation=_installation(sync.capture, cfg.installation))
    clock = SimClock(0.0, float(cap.start_unix))
    if not bulk:
        svc = Service(rcfg, params, clock=clock, driver_clock=sync.clock, drivers=sync.drivers,
                      publisher=publisher, driver_threads=False, before_tick=sync.step,
                      record_stats=record_stats, close_truck_at_end=close_truck_at_end)
        sync.attach({n: svc.store.sink(n, threaded=False) for n in devices})  # one thread
        return ReplayRun(svc, sync, None)
    from drivers.base import DriverHealth
    from shoveld.replay.bulk import BulkAssembler, BulkFeed, BulkSession, ReplayedDriver

    drivers: dict[str, Any] = {n: ReplayedDriver(n, DriverHealth()) for n in devices}
    svc = Service(rcfg, params, clock=clock, driver_clock=sync.clock, drivers=drivers,
                  publisher=publisher, driver_threads=False, record_stats=record_stats,
                  close_truck_at_end=close_truck_at_end)
    feed = BulkFeed(sync, rcfg.installation, rcfg.loop.rate_hz, rcfg.loop.health_period_s)
    svc.assembler = assembler = BulkAssembler(feed, drivers, svc.store)
    return ReplayRun(svc, BulkSession(sync, assembler), None)


def replay_service(capture_dir: str | Path, cfg: DaemonConfig, params: ModelParams,
                   speed: float | None = None, *, record_stats: bool = False,
                   close_truck_at_end: bool = True, **replay_kw: Any) -> ReplayRun:
    """Open the capture on the drivers' virtual hardware and build the service on it
    (not started): paced at ``speed``, or on the stepped replay clock (None)."""
    from drivers.capture.replay import open_replay

    # paced: the recording waits for the service to start (ReplayRun.run starts it); its
    # drivers' handshakes are answered meanwhile. Until 2026-11-30 it ran from here, and
    # on a slow machine the MTi's stream filled its port before the driver read it (the
    # paced test of the committed capture failed 1 run in 3: pass 1 up to 7 % heavy).
    session = open_replay(capture_dir, speed=speed, hold=speed is not None, **replay_kw)
    try:
        cap = session.capture
        devices = replay_devices(session, cfg.loop.max_age_s)
        rcfg = dataclasses.replace(cfg, devices=devices,
                                   installation=_installation(cap, cfg.installation))
        origin = float(cap.start_unix)
        clock = (ReplayStepClock(session.clock, origin) if speed is None
                 else ReplayPacedClock(session.clock, origin))
        svc = Service(rcfg, params, clock=clock, driver_clock=session.clock,
                      record_stats=record_stats, close_truck_at_end=close_truck_at_end)
    except BaseException:
        session.close()
        raise
    return ReplayRun(svc, session, speed)
