"""The daemon's configuration file (TOML): read, check, and refuse with the key named.

One file says everything a shovel's computer needs: which devices to open and how
(their tables are handed to the drivers' own ``from_config``, so a driver key is
checked by the driver that uses it), the installation survey, the calibrated
parameters, the loop rate, Zenoh, and the truck target. Every mistake is reported
as ``FILE: key 'section.key' ...`` so the installer knows what to fix; a daemon with
a bad file refuses to start instead of guessing.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from shoveld import keys
from shoveld.cycle.phases import PhaseConfig
from shoveld.endpoints import endpoint_error
from shoveld.engine.loop import NEEDED, EngineConfig
from shoveld.installation import Installation
from shoveld.paths import DEFAULT_CONFIG as DEFAULT_CONFIG  # re-exported
from shoveld.payload.rls import RlsConfig
from shoveld.sample import SIGNAL_FIELDS

MTI_KINDS = ("mti_serial", "mti_can")
LASER_KINDS = ("ar4000",)
ADC_KINDS = ("modbus_tcp", "modbus_rtu")
KINDS = MTI_KINDS + LASER_KINDS + ADC_KINDS

DEVICE_SIGNALS = tuple(c for c in SIGNAL_FIELDS if c not in ("time_s", "payload_kg"))
"""Signals-table columns a device can provide."""

DAEMON_DEVICE_KEYS = ("max_age_s", "enabled")
"""Keys of ``[devices.<name>]`` the daemon reads itself; all others go to the driver."""

class ConfigError(ValueError):
    """A configuration the daemon will not run with; the message names file and key."""


@dataclass(frozen=True)
class DeviceConfig:
    """One ``[devices.<name>]`` table, split into daemon keys and the driver's table."""

    name: str
    kind: str
    driver: dict[str, Any]
    """Passed to the driver's ``from_config`` (includes ``kind``)."""
    max_age_s: float
    """A reading older than this at the tick is stale: its signals are invalid."""
    signals: tuple[str, ...]
    """Signals-table columns this device provides (derived from kind and channels)."""


@dataclass(frozen=True)
class LoopConfig:
    rate_hz: float = 100.0
    max_age_s: float = 0.25
    """Default staleness limit for every device (``devices.<name>.max_age_s`` overrides)."""
    ready_timeout_s: float = 10.0
    """READY=1 is sent when all drivers are connected, or after this many seconds."""
    health_period_s: float = 1.0
    watchdog_max_late_s: float = 2.0
    """No watchdog ping while the loop is this far behind its schedule."""
    sync: str = "none"
    """Device whose readings the ticks are phase-locked to (``none``: free-running)."""
    sync_delay_s: float = 0.001
    """With ``sync``: ticks fall this long after the master's readings arrive."""
    align_polls: bool = False
    """Host-polled devices (Modbus) time their polls to answer just before a tick
    (default: on when ``sync`` is)."""


@dataclass(frozen=True)
class TlsConfig:
    """``[zenoh.tls]``: mutual TLS with the site CA (see ``shoveld pki``)."""

    ca: Path
    """The site CA certificate: peers must present a certificate it signed."""
    certificate: Path
    """This shovel's certificate (common name = ``shovel.id``)."""
    key: Path
    """Its private key (owner-only)."""
    access_control: bool = True
    """Also apply the daemon's own access-control list (``shoveld.security.acl``)."""


@dataclass(frozen=True)
class ZenohConfig:
    mode: str = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    prefix: str = "shovel"
    joints_rate_hz: float = 10.0
    live_rate_hz: float = 10.0
    extra: dict[str, Any] = field(default_factory=dict)
    """``[zenoh.config]``: raw Zenoh config keys (``"transport/unicast/max_links" = 4``)."""
    tls: TlsConfig | None = None
    """``[zenoh.tls]``: every endpoint is then ``tls/``."""
    acl: dict[str, Any] | None = None
    """The ``access_control`` section the session is opened with (from ``tls``)."""


@dataclass(frozen=True)
class DaemonConfig:
    """Everything ``shoveld run`` needs, checked."""

    path: Path | None
    shovel_id: str
    params_path: Path
    state_dir: Path
    loop: LoopConfig
    zenoh: ZenohConfig
    installation: Installation
    engine: EngineConfig
    devices: dict[str, DeviceConfig]
    log_level: str = "info"
    rule_window_h: float = 12.0
    """Trucks closed within this many hours count in the 10/10/20 summary (a shift)."""

    def with_devices(self, devices: dict[str, DeviceConfig]) -> DaemonConfig:
        return dataclasses.replace(self, devices=devices)


# -- helpers -------------------------------------------------------------------------------

class _Reader:
    """Typed access to one table with error messages naming ``file: key 'a.b'``."""

    def __init__(self, where: str, d: Mapping[str, Any], prefix: str) -> None:
        self.where = where
        self.d = d
        self.prefix = prefix
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.prefix}{k}"

    def fail(self, k: str, why: str) -> ConfigError:
        return ConfigError(f"{self.where}: key '{self.key(k)}' {why}")

    def has(self, k: str) -> bool:
        return k in self.d

    def number(self, k: str, default: float | None = None, *, lo: float | None = None,
               hi: float | None = None, positive: bool = False) -> float:
        self.used.add(k)
        if k not in self.d:
            if default is None:
                raise self.fail(k, "is required (a number)")
            return default
        v = self.d[k]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise self.fail(k, f"must be a number, got {v!r}")
        v = float(v)
        if positive and not v > 0:
            raise self.fail(k, f"must be > 0, got {v!r}")
        if lo is not None and v < lo:
            raise self.fail(k, f"must be >= {lo:g}, got {v!r}")
        if hi is not None and v > hi:
            raise self.fail(k, f"must be <= {hi:g}, got {v!r}")
        return v

    def string(self, k: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        self.used.add(k)
        if k not in self.d:
            if default is None:
                raise self.fail(k, "is required (a string)")
            return default
        v = self.d[k]
        if not isinstance(v, str) or not v:
            raise self.fail(k, f"must be a non-empty string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.fail(k, f"must be one of {list(choices)}, got {v!r}")
        return v

    def boolean(self, k: str, default: bool) -> bool:
        self.used.add(k)
        v = self.d.get(k, default)
        if not isinstance(v, bool):
            raise self.fail(k, f"must be true or false, got {v!r}")
        return v

    def strings(self, k: str, default: tuple[str, ...]) -> tuple[str, ...]:
        self.used.add(k)
        v = self.d.get(k, list(default))
        if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
            raise self.fail(k, f"must be a list of strings, got {v!r}")
        return tuple(v)

    def table(self, k: str) -> Mapping[str, Any]:
        self.used.add(k)
        v = self.d.get(k, {})
        if not isinstance(v, Mapping):
            raise self.fail(k, "must be a table")
        return v

    def done(self) -> None:
        """Unknown keys are errors: a typo must not silently fall back to a default."""
        for k in self.d:
            if k not in self.used:
                raise self.fail(k, f"is not a known key (known: {sorted(self.used)})")


def _dataclass_from(where: str, cls: type, d: Mapping[str, Any], prefix: str,
                    skip: tuple[str, ...] = ()) -> Any:
    """Build a dataclass of numbers from a table (engine, phases, rls, installation);
    the field defaults give the types, the class's ``RANGES`` (if any) each number's
    range, and unknown keys are errors."""
    r = _Reader(where, d, prefix)
    base = cls()
    ranges: dict[str, dict[str, Any]] = getattr(cls, "RANGES", {})
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        default = getattr(base, f.name)
        if f.name in skip or not isinstance(default, bool | int | float):
            continue
        r.used.add(f.name)
        if not r.has(f.name):
            continue
        if isinstance(default, bool):
            kw[f.name] = r.boolean(f.name, default)
        elif isinstance(default, int):
            v = r.number(f.name, float(default), **ranges.get(f.name, {}))
            if v != int(v):
                raise r.fail(f.name, f"must be an integer, got {v!r}")
            kw[f.name] = int(v)
        else:
            kw[f.name] = r.number(f.name, default, **ranges.get(f.name, {}))
    r.done()
    return cls(**kw)


def _path(where_dir: Path | None, s: str) -> Path:
    p = Path(s).expanduser()
    if not p.is_absolute() and where_dir is not None:
        p = where_dir / p
    return p


# -- devices -------------------------------------------------------------------------------

def device_signals(kind: str, driver: Mapping[str, Any]) -> tuple[str, ...]:
    """The signals-table columns a device of this kind provides."""
    if kind in MTI_KINDS:
        return ("handle_deg", "swing_deg")
    if kind in LASER_KINDS:
        return ("crowd_m",)
    chans = driver.get("channels") or []
    if not isinstance(chans, list):
        return ()  # the driver's own check names the key
    return tuple(c["name"] for c in chans if isinstance(c, Mapping) and "name" in c)


def build_driver(dev: DeviceConfig, clock: Any = None, **kw: Any) -> Any:
    """The driver object of one device (not opened): the drivers' own constructors.

    ``kw`` goes to the driver (``serial_factory``, ``bus_factory``, ``client_factory``)."""
    import time as _time

    clk = clock if clock is not None else _time.monotonic
    d = dict(dev.driver)
    if dev.kind == "ar4000":
        from drivers.acuity.ar4000 import Ar4000Driver

        return Ar4000Driver.from_config(dev.name, d, clock=clk, **kw)
    if dev.kind == "mti_serial":
        from drivers.xsens.serial_driver import MtiSerialDriver

        d.pop("kind", None)
        d.setdefault("name", dev.name)
        return MtiSerialDriver.from_config(d, clock=clk, **kw)
    if dev.kind == "mti_can":
        from drivers.xsens.can_driver import MtiCanDriver

        d.pop("kind", None)
        d.setdefault("name", dev.name)
        return MtiCanDriver.from_config(d, clock=clk, **kw)
    from drivers.modbus_adc.driver import ModbusAdcDriver

    return ModbusAdcDriver.from_config(dev.name, d, clock=clk, **kw)


def parse_devices(where: str, devs: Any, default_max_age: float,
                  check_drivers: bool = True, coverage: bool = True
                  ) -> dict[str, DeviceConfig]:
    """``[devices.*]`` tables -> DeviceConfig, each checked by its driver's from_config;
    with ``coverage``, together they must provide every signal the payload needs."""
    if not isinstance(devs, Mapping) or not devs:
        raise ConfigError(f"{where}: needs at least one [devices.<name>] table")
    out: dict[str, DeviceConfig] = {}
    for name, d in devs.items():
        if not isinstance(d, Mapping):
            raise ConfigError(f"{where}: key 'devices.{name}' must be a table")
        if not keys.CHUNK.fullmatch(name):
            raise ConfigError(f"{where}: key 'devices.{name}': device names may only use "
                              "letters, digits, '_', '.', '-'")
        kind = d.get("kind")
        if kind not in KINDS:
            raise ConfigError(f"{where}: key 'devices.{name}.kind' must be one of "
                              f"{list(KINDS)}, got {kind!r}")
        r = _Reader(where, d, f"devices.{name}.")
        max_age = r.number("max_age_s", default_max_age, positive=True)
        if "enabled" in d and not r.boolean("enabled", True):
            continue
        driver = {k: v for k, v in d.items() if k not in DAEMON_DEVICE_KEYS}
        dev = DeviceConfig(name, kind, driver, max_age, device_signals(kind, driver))
        if check_drivers:
            try:
                build_driver(dev)
            except (ValueError, TypeError, KeyError, AttributeError) as e:
                # A driver's from_config given a key of the wrong type (channels = 7, a
                # port as a list) fails with TypeError or KeyError, not only ValueError.
                raise ConfigError(f"{where}: [devices.{name}]: {e}") from None
        for s in dev.signals:
            if s not in DEVICE_SIGNALS:
                raise ConfigError(f"{where}: key 'devices.{name}.channels': channel name "
                                  f"{s!r} is not a signals-table column (one of "
                                  f"{list(DEVICE_SIGNALS)})")
        out[name] = dev
    if coverage:
        check_coverage(where, out)
    return out


def check_coverage(where: str, devices: Mapping[str, DeviceConfig]) -> None:
    """Every signal the payload needs has exactly one source."""
    provider: dict[str, str] = {}
    for dev in devices.values():
        for s in dev.signals:
            if s in provider:
                raise ConfigError(f"{where}: signal '{s}' is provided by both "
                                  f"'devices.{provider[s]}' and 'devices.{dev.name}'")
            provider[s] = dev.name
    missing = [s for s in NEEDED if s not in provider]
    if missing:
        raise ConfigError(f"{where}: key 'devices': no device provides {missing}, which the "
                          "payload needs (an MTi for handle_deg, an AR4000 for crowd_m, ADC "
                          "channels named hoist1_a, hoist2_a, hoist_field_a, crowd_a)")


def device_rate_hz(dev: DeviceConfig) -> float | None:
    """The rate a device is configured to deliver readings at, where its config says."""
    d = dev.driver
    try:
        if dev.kind == "mti_serial":
            return float(d.get("rate_hz", 100))
        if dev.kind in LASER_KINDS:
            return 1e6 / float(d.get("sample_interval_us", 20000))
        if dev.kind in ADC_KINDS:
            return float(d.get("poll_hz", 50.0))
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return None  # mti_can: the rate is set in the device, not in this file


def check_sync(where: str, loop: LoopConfig, devices: Mapping[str, DeviceConfig]) -> None:
    """``loop.sync`` names a device whose rate the loop rate is a whole multiple of."""
    if loop.sync == "none":
        return
    if loop.sync not in devices:
        raise ConfigError(f"{where}: key 'loop.sync' must be \"none\" or a device name (one "
                          f"of {sorted(devices)}), got {loop.sync!r}")
    rate = device_rate_hz(devices[loop.sync])
    if rate is not None:
        ratio = loop.rate_hz / rate
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(
                f"{where}: key 'loop.sync': device '{loop.sync}' delivers {rate:g} readings/s; "
                f"the phase lock needs a loop rate ({loop.rate_hz:g} Hz) that is a whole "
                "multiple of it")


def check_align(where: str, loop: LoopConfig, devices: Mapping[str, DeviceConfig]) -> None:
    """An explicit ``loop.align_polls = true`` needs polls no faster than the ticks (each
    poll gets its own tick); by default such a device just keeps its own schedule."""
    if not loop.align_polls:
        return
    for dev in devices.values():
        rate = device_rate_hz(dev) if dev.kind in ADC_KINDS else None
        if rate is not None and rate > loop.rate_hz * (1.0 + 1e-9):
            raise ConfigError(
                f"{where}: key 'loop.align_polls': device '{dev.name}' polls at {rate:g} Hz, "
                f"faster than the loop ({loop.rate_hz:g} Hz), so its polls cannot each be "
                "timed for a tick; lower its poll_hz or set align_polls = false")


# -- the file ------------------------------------------------------------------------------

def _check_zenoh_extra(where: str, extra: Mapping[str, Any]) -> None:
    """Raw Zenoh keys are checked by Zenoh itself, now rather than at every retry."""
    if not extra:
        return
    import json

    import zenoh

    c = zenoh.Config()
    for k, v in extra.items():
        try:
            c.insert_json5(k, json.dumps(v))
        except Exception as e:  # noqa: BLE001 - zenoh.ZError
            from shoveld.daemon.publisher import zenoh_words

            raise ConfigError(f"{where}: key 'zenoh.config.{k}': Zenoh refuses it "
                              f"({zenoh_words(e)})") from None


def _parse_tls(where: str, t: Mapping[str, Any], base_dir: Path | None) -> TlsConfig:
    r = _Reader(where, t, "zenoh.tls.")
    tls = TlsConfig(ca=_path(base_dir, r.string("ca")),
                    certificate=_path(base_dir, r.string("certificate")),
                    key=_path(base_dir, r.string("key")),
                    access_control=r.boolean("access_control", True))
    r.done()
    return tls


def check_tls_files(cfg: DaemonConfig, dates: bool = True) -> list[str]:
    """The TLS files exist, are readable and (with ``dates``) in date, the certificate is
    this shovel's and signed by the CA, the key is the certificate's and the owner's
    only; ConfigError names the key and file. Returns notes for check-config."""
    tls = cfg.zenoh.tls
    if tls is None:
        return []
    from shoveld.security.pki import CertInfo, PeerFileError, PkiError, check_peer_files

    def this_shovel(info: CertInfo) -> None:
        if info.role not in (None, "shovel") or info.common_name != cfg.shovel_id:
            raise PkiError(
                f"{info.path} is for {info.common_name!r} (role {info.role}), not shovel "
                f"{cfg.shovel_id!r}: the routers let it publish only under "
                f"{cfg.zenoh.prefix}/{info.common_name}/")

    where = str(cfg.path) if cfg.path else "<config>"
    try:
        ca, info = check_peer_files(tls.ca, tls.certificate, tls.key, dates, this_shovel)
    except PeerFileError as e:
        raise ConfigError(f"{where}: key 'zenoh.tls.{e.which}': {e}") from None
    return [f"{k} {c.path}: {c.common_name!r}, valid until {c.not_after:%Y-%m-%d}"
            for k, c in (("ca", ca), ("certificate", info))]


def parse_config(doc: Mapping[str, Any], where: str = "<config>",
                 base_dir: Path | None = None, check_drivers: bool = True,
                 require_devices: bool = True) -> DaemonConfig:
    """Check a parsed TOML document and build the DaemonConfig."""
    top = _Reader(where, doc, "")
    sh = _Reader(where, top.table("shovel"), "shovel.")
    shovel_id = sh.string("id", "shovel")
    if not keys.NAME.fullmatch(shovel_id):
        raise sh.fail("id", f"may only use 1-64 letters, digits, '_', '.', '-' (it is a Zenoh "
                            f"key chunk and the common name of its certificate), got "
                            f"{shovel_id!r}")
    params = _path(base_dir, sh.string("params"))
    state_dir = _path(base_dir, sh.string("state_dir", "/var/lib/shoveld"))
    log_level = sh.string("log_level", "info", ("debug", "info", "warning", "error"))
    sh.done()

    lp = _Reader(where, top.table("loop"), "loop.")
    loop = LoopConfig(rate_hz=lp.number("rate_hz", 100.0, lo=1.0, hi=1000.0),
                      max_age_s=lp.number("max_age_s", 0.25, positive=True),
                      ready_timeout_s=lp.number("ready_timeout_s", 10.0, lo=0.0),
                      health_period_s=lp.number("health_period_s", 1.0, positive=True),
                      watchdog_max_late_s=lp.number("watchdog_max_late_s", 2.0, positive=True),
                      sync=lp.string("sync", "none"))
    loop = dataclasses.replace(loop, sync_delay_s=lp.number(
        "sync_delay_s", 0.001, lo=0.0, hi=0.5 / loop.rate_hz),
        align_polls=lp.boolean("align_polls", loop.sync != "none"))
    align_explicit = lp.has("align_polls")
    lp.done()

    zr = _Reader(where, top.table("zenoh"), "zenoh.")
    mode = zr.string("mode", "peer", ("peer", "client", "router"))
    proto = "tls" if zr.has("tls") else "tcp"
    listen = zr.strings("listen", (f"{proto}/127.0.0.1:7447",) if mode != "client" else ())
    connect = zr.strings("connect", ())
    for k, eps in (("listen", listen), ("connect", connect)):
        for ep in eps:
            why = endpoint_error(ep)
            if why:
                raise zr.fail(k, why)
    if mode == "client" and not connect:
        raise zr.fail("connect", "is required in client mode (the site's router endpoints)")
    prefix = zr.string("prefix", "shovel")
    if not keys.PREFIX.fullmatch(prefix):
        raise zr.fail("prefix", f"must be a plain key expression, got {prefix!r}")
    zc = ZenohConfig(mode=mode, listen=listen, connect=connect,
                     multicast_scouting=zr.boolean("multicast_scouting", False),
                     prefix=prefix,
                     joints_rate_hz=zr.number("joints_rate_hz", 10.0, positive=True,
                                              hi=loop.rate_hz),
                     live_rate_hz=zr.number("live_rate_hz", 10.0, positive=True,
                                            hi=loop.rate_hz),
                     extra=dict(zr.table("config")))
    if zr.has("tls"):
        tls = _parse_tls(where, zr.table("tls"), base_dir)
        for k, eps in (("listen", listen), ("connect", connect)):
            for ep in eps:
                if not ep.startswith("tls/"):
                    raise zr.fail(k, f"endpoint {ep!r} is plaintext but [zenoh.tls] asks for "
                                     "TLS: use 'tls/HOST:PORT'")
        acl = None
        if tls.access_control:
            from shoveld.security.acl import daemon_acl

            acl = daemon_acl(prefix, shovel_id)
        zc = dataclasses.replace(zc, tls=tls, acl=acl)
    zr.done()
    _check_zenoh_extra(where, zc.extra)

    inst = _dataclass_from(where, Installation, top.table("installation"), "installation.")
    if inst.crowd_gain == 0 or inst.handle_pitch_sign == 0 or inst.swing_yaw_sign == 0:
        raise ConfigError(f"{where}: key 'installation': crowd_gain, handle_pitch_sign and "
                          "swing_yaw_sign must not be 0")

    tr = _Reader(where, top.table("truck"), "truck.")
    target = tr.number("target_kg", 136000.0, positive=True)
    gap = tr.number("gap_s", 20.0, positive=True)
    rule_window_h = tr.number("rule_window_h", 12.0, positive=True)
    tr.done()

    en_table = dict(top.table("engine"))
    phases_t = en_table.pop("phases", {})
    rls_t = en_table.pop("rls", {})
    for k, t in (("engine.phases", phases_t), ("engine.rls", rls_t)):
        if not isinstance(t, Mapping):
            raise ConfigError(f"{where}: key '{k}' must be a table")
    for k in ("rate_hz", "truck_target_kg", "truck_gap_s"):
        if k in en_table:
            raise ConfigError(f"{where}: key 'engine.{k}' is set elsewhere ("
                              f"{'loop.rate_hz' if k == 'rate_hz' else 'truck.*'})")
    eng_base = _dataclass_from(where, EngineConfig, en_table, "engine.",
                               skip=("phases", "rls", "rate_hz", "truck_target_kg",
                                     "truck_gap_s"))
    engine = dataclasses.replace(
        eng_base, rate_hz=loop.rate_hz, truck_target_kg=target, truck_gap_s=gap,
        phases=_dataclass_from(where, PhaseConfig, phases_t, "engine.phases."),
        rls=_dataclass_from(where, RlsConfig, rls_t, "engine.rls."))
    ph = engine.phases
    if not ph.tuck_deg < ph.dig_exit_deg:
        raise ConfigError(f"{where}: key 'engine.phases.tuck_deg' must be below "
                          f"'dig_exit_deg' (a dig starts below the one and leaves the bank "
                          f"above the other), got {ph.tuck_deg:g} and {ph.dig_exit_deg:g}")
    if ph.swing_off_deg_s > ph.swing_on_deg_s:
        raise ConfigError(f"{where}: key 'engine.phases.swing_off_deg_s' must be at most "
                          f"'swing_on_deg_s', got {ph.swing_off_deg_s:g} and "
                          f"{ph.swing_on_deg_s:g}")

    devs_t = top.table("devices")
    if devs_t or require_devices:
        # (a command that ignores the devices, replay, takes a config whose devices do
        # not cover the payload: it was refused with the coverage's message)
        devices = parse_devices(where, devs_t, loop.max_age_s, check_drivers,
                                coverage=require_devices)
    else:
        devices = {}
    if devices:
        check_sync(where, loop, devices)
        if align_explicit:
            check_align(where, loop, devices)
    top.done()
    return DaemonConfig(path=None, shovel_id=shovel_id, params_path=params, state_dir=state_dir,
                        loop=loop, zenoh=zc, installation=inst, engine=engine, devices=devices,
                        log_level=log_level, rule_window_h=rule_window_h)


def load_config(path: str | Path, check_drivers: bool = True,
                require_devices: bool = True) -> DaemonConfig:
    """Read and check a config file; relative paths in it are relative to the file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"{p}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{p}: not a text file (byte {e.start} is not UTF-8); expected the "
                          "daemon's TOML configuration") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML: {e}") from None
    cfg = parse_config(doc, str(p), p.resolve().parent, check_drivers, require_devices)
    return dataclasses.replace(cfg, path=p)


def check_params(cfg: DaemonConfig) -> Any:
    """Load the calibrated parameters the config names (ConfigError names the key)."""
    from shoveld.model.params import ParamsFileError, load_params

    where = str(cfg.path) if cfg.path else "<config>"
    try:
        return load_params(cfg.params_path)
    except ParamsFileError as e:
        raise ConfigError(f"{where}: key 'shovel.params': {e}") from None
