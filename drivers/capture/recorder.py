"""Record live devices into a capture by running the real drivers with taps.

The drivers configure their devices exactly as the daemon would, so a capture
holds the device's stream *after* shoveld's configuration, plus the handshake
itself (serial ``tx``/``rx`` chunks) for replay to answer. Serial drivers record
through a transport tap (every chunk read and written), Modbus drivers through
their ``register_log`` hook (every register read and its outcome), CAN drivers
through a bus tap whose frames go to python-can's :class:`can.Logger`.

Configuration (TOML, the daemon's format until it is final)::

    [installation]            # optional: shoveld.installation.Installation fields
    crowd_offset_m = 5.88

    [devices.<name>]
    kind = "ar4000" | "mti_serial" | "mti_can" | "modbus_tcp" | "modbus_rtu"
    ...                       # the driver's own keys (docs/captures.md)
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.base import Driver, Reading
from drivers.capture.format import KINDS, CaptureWriter
from drivers.capture.tap import TappedSerial

log = logging.getLogger(__name__)


class TappedBus:
    """A python-can bus whose received frames are also logged (the CAN recording tap)."""

    def __init__(self, bus: Any, log_frame: Callable[[Any], None]) -> None:
        self._bus = bus
        self._log = log_frame

    def recv(self, timeout: float | None = None) -> Any:
        msg = self._bus.recv(timeout=timeout)
        if msg is not None:
            self._log(msg)
        return msg

    def shutdown(self) -> None:
        self._bus.shutdown()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._bus, name)


class RecordConfigError(ValueError):
    """A recorder configuration problem; the message names the file/section/key."""


def load_record_config(path: str | Path) -> dict[str, Any]:
    """Read and check the TOML configuration (sections and kinds; driver keys later)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise RecordConfigError(f"{p}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise RecordConfigError(f"{p}: not a text file (byte {e.start} is not UTF-8); "
                                "expected a TOML configuration") from None
    except tomllib.TOMLDecodeError as e:
        raise RecordConfigError(f"{p}: not valid TOML: {e}") from None
    check_record_config(data, str(p))
    return data


def check_record_config(data: Mapping[str, Any], where: str = "<config>") -> None:
    devs = data.get("devices")
    if not isinstance(devs, Mapping) or not devs:
        raise RecordConfigError(f"{where}: needs at least one [devices.<name>] section")
    for name, d in devs.items():
        if not isinstance(d, Mapping):
            raise RecordConfigError(f"{where}: [devices.{name}] must be a table")
        kind = d.get("kind")
        if kind not in KINDS:
            raise RecordConfigError(f"{where}: [devices.{name}] key 'kind' must be one of "
                                    f"{sorted(KINDS)}, got {kind!r}")
    inst = data.get("installation")
    if inst is not None:
        _installation(inst, where)


def _installation(d: Any, where: str) -> Any:
    from shoveld.installation import Installation

    if not isinstance(d, Mapping):
        raise RecordConfigError(f"{where}: [installation] must be a table")
    known = {f.name for f in dataclasses.fields(Installation)}
    for k, v in d.items():
        if k not in known:
            raise RecordConfigError(f"{where}: [installation] unknown key {k!r}; known: "
                                    f"{sorted(known)}")
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise RecordConfigError(f"{where}: [installation] key {k!r} must be a number")
    return Installation(**{k: float(v) for k, v in d.items()})


@dataclass
class _Device:
    name: str
    kind: str
    driver: Driver | None = None
    readings: int = 0
    invalid: int = 0
    thread: threading.Thread | None = None
    cleanup: list[Callable[[], None]] = field(default_factory=list)

    def sink(self, r: Reading) -> None:
        self.readings += 1
        if r.invalid:
            self.invalid += 1


class Recorder:
    """Runs one driver per configured device and writes everything into a capture."""

    def __init__(self, config: Mapping[str, Any], out_dir: str | Path, *,
                 clock: Callable[[], float] = time.monotonic, source: str = "shoveld record",
                 overwrite: bool = False, where: str = "<config>",
                 time_origin: float | None = None) -> None:
        check_record_config(config, where)
        self.config = config
        self.clock = clock
        inst = config.get("installation")
        installation = _installation(inst, where) if inst is not None else None
        # Every device's driver from its keys before the capture is opened: a refused key
        # leaves the output folder as it was (no empty capture made, and an --overwrite
        # keeps the old capture whole). Nothing is opened here: the drivers open their
        # ports when they run, and take their taps then.
        built = [self._build(name, dict(d), where) for name, d in config["devices"].items()]
        self.writer = CaptureWriter(out_dir, installation=installation, source=source,
                                    clock=clock, overwrite=overwrite, time_origin=time_origin)
        self.devices: list[_Device] = []
        self._stop = threading.Event()
        try:
            for dev, tap in built:
                tap(self.writer)
                self.devices.append(dev)
        except Exception:
            self.writer.close(0.0)
            raise

    # -- device construction ---------------------------------------------------------------

    def _build(self, name: str, d: dict[str, Any], where: str
               ) -> tuple[_Device, Callable[[CaptureWriter], None]]:
        """The device's driver from its keys, and how to put its tap into a capture."""
        kind = d["kind"]
        dev = _Device(name, kind)
        tap: Callable[[CaptureWriter], None]
        try:
            if kind == "ar4000":
                from drivers.acuity.ar4000 import Ar4000Config, Ar4000Driver

                cfg = Ar4000Config.from_config(d)
                drv = Ar4000Driver(name, cfg, clock=self.clock)
                dev.driver = drv

                def tap(w: CaptureWriter) -> None:
                    drv.tap = w.add_serial(name, kind, port=cfg.port, baudrate=cfg.baudrate,
                                           config=d)
            elif kind == "mti_serial":
                import serial

                from drivers.xsens.serial_driver import ORIENTATIONS, MtiSerialDriver

                args = {k: v for k, v in d.items() if k != "kind"}
                taps: list[Any] = []

                def factory(*a: Any, **kw: Any) -> Any:
                    return TappedSerial(serial.Serial(*a, **kw), taps[0])

                args.setdefault("name", name)
                dev.driver = MtiSerialDriver.from_config(args, clock=self.clock,
                                                         serial_factory=factory)

                def tap(w: CaptureWriter) -> None:
                    # the orientation and the extra outputs are recorded even when they
                    # are the default: the defaults changed, and a replay must configure
                    # what the device sent
                    taps.append(w.add_serial(
                        name, kind, port=d.get("port"), baudrate=d.get("baudrate", 115200),
                        config={**d, "orientation": d.get("orientation", ORIENTATIONS[0]),
                                "extra_outputs": list(d.get("extra_outputs", ()))}))
            elif kind == "mti_can":
                tap = self._build_can(dev, d)
            else:
                from drivers.modbus_adc.driver import ModbusAdcConfig, ModbusAdcDriver

                mcfg = ModbusAdcConfig.from_config(d)
                adc = ModbusAdcDriver(name, mcfg, clock=self.clock)
                dev.driver = adc

                def tap(w: CaptureWriter) -> None:
                    adc.register_log = w.add_modbus(name, kind, config=mcfg.to_config())
        except ValueError as e:
            raise RecordConfigError(f"{where}: [devices.{name}]: {e}") from None
        return dev, tap

    def _build_can(self, dev: _Device, d: dict[str, Any]) -> Callable[[CaptureWriter], None]:
        import can

        from drivers.xsens.can_driver import MtiCanDriver

        args = {k: v for k, v in d.items() if k != "kind"}
        args.setdefault("name", dev.name)
        if "channel" not in args:
            raise ValueError("key 'channel' is required (e.g. 'can0')")
        recs: list[Any] = []

        def factory(**kw: Any) -> Any:
            return TappedBus(can.Bus(**kw), recs[0])

        dev.driver = MtiCanDriver.from_config(args, clock=self.clock, bus_factory=factory)

        def tap(w: CaptureWriter) -> None:
            recs.append(w.add_can(dev.name, dev.kind, channel=args["channel"],
                                  interface=args.get("interface", "socketcan"),
                                  bitrate=args.get("bitrate"), config=d))
        return tap

    # -- running -------------------------------------------------------------------------

    def start(self) -> Recorder:
        for dev in self.devices:
            if dev.driver is not None:
                dev.thread = threading.Thread(target=dev.driver.run, args=(dev.sink, self._stop),
                                              name=f"record-{dev.name}", daemon=True)
                dev.thread.start()
        return self

    def stop(self) -> dict[str, dict[str, Any]]:
        """Stop the drivers, close the capture, return a per-device summary."""
        self._stop.set()
        for dev in self.devices:
            if dev.thread is not None:
                dev.thread.join(timeout=5)
            for fn in dev.cleanup:
                try:
                    fn()
                except Exception:  # noqa: BLE001
                    log.exception("%s: cleanup", dev.name)
        self.writer.close()
        return self.summary()

    def summary(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        for dev in self.devices:
            s: dict[str, Any] = {"kind": dev.kind, "readings": dev.readings,
                                 "invalid": dev.invalid}
            if dev.driver is not None:
                h = dev.driver.health
                s.update(connected=h.connected, reconnects=h.reconnects,
                         bad_frames=h.bad_frames, timeouts=h.timeouts, last_error=h.last_error)
            out[dev.name] = s
        return out

    def run(self, duration_s: float | None, stop: threading.Event | None = None
            ) -> dict[str, dict[str, Any]]:
        """Record for ``duration_s`` capture seconds (None: until ``stop`` is set)."""
        self.start()
        stop = stop or threading.Event()
        t_end = None if duration_s is None else self.writer.now() + duration_s
        try:
            while not stop.is_set():
                if t_end is not None and self.writer.now() >= t_end:
                    break
                stop.wait(0.05)
        finally:
            summary = self.stop()
        return summary
