"""The simulated shovel as byte streams: every emulator driven by one signals table.

:class:`VirtualShovel` starts the AR4000 emulator (crowd -> laser distance), the
MTi emulator (handle angle -> pitch, swing -> yaw; serial or CAN), and two Modbus
analog-input modules (motor currents; cab inclinometers), all reading the same
table on the same clock. Real drivers then connect to ``shovel.config()`` exactly
as to hardware, which is how ``make_capture`` turns simulated cycles into
captures and how the daemon can be tested end to end.

:class:`DriverRunner` runs one driver in a thread and collects its readings
(tests, capture making, quick experiments).
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

from drivers.base import Driver, Reading
from drivers.capture.clock import ReplayClock
from drivers.modbus_adc.channels import ChannelMap
from hil_fixtures.ar4000 import Ar4000Emulator
from hil_fixtures.ar4000 import source_from_table as laser_source
from hil_fixtures.modbus_adc import ModbusAdcEmulator
from hil_fixtures.modbus_adc import source_from_table as adc_source
from shoveld.installation import Installation
from shoveld.signals import SignalsTable

#: Motor currents: +-10 V modules, 4000 A Hall transducers (400 A/V) on armatures,
#: 200 A transducers (20 A/V) on fields.
MOTOR_CHANNELS = ChannelMap.from_config([
    {"name": "hoist1_a", "register": 0, "scale": 400.0},
    {"name": "hoist2_a", "register": 1, "scale": 400.0},
    {"name": "hoist_field_a", "register": 2, "scale": 20.0},
    {"name": "crowd_a", "register": 3, "scale": 400.0},
    {"name": "crowd_field_a", "register": 4, "scale": 20.0},
    {"name": "swing_a", "register": 5, "scale": 400.0},
    {"name": "swing_field_a", "register": 6, "scale": 20.0},
])
#: Inclinometers: boom 0..90 deg over +-10 V; house roll/pitch +-30 deg over +-10 V.
INCLINOMETER_CHANNELS = ChannelMap.from_config([
    {"name": "boom_deg", "register": 0, "scale": 4.5, "offset": 45.0},
    {"name": "roll_deg", "register": 1, "scale": 3.0},
    {"name": "pitch_deg", "register": 2, "scale": 3.0},
])


class DriverRunner:
    """Runs ``driver.run`` in a thread and keeps every reading (thread-safe list)."""

    def __init__(self, driver: Driver, on_reading: Callable[[Reading], None] | None = None
                 ) -> None:
        self.driver = driver
        self.readings: list[Reading] = []
        self._on = on_reading
        self._stop = threading.Event()
        self._thread = threading.Thread(target=driver.run, args=(self._sink, self._stop),
                                        name=f"driver-{driver.name}", daemon=True)

    def _sink(self, r: Reading) -> None:
        self.readings.append(r)
        if self._on is not None:
            self._on(r)

    def start(self) -> DriverRunner:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def wait_for(self, pred: Callable[[], bool], timeout: float = 5.0,
                 step: Callable[[], object] | None = None) -> bool:
        """Poll ``pred`` (calling ``step`` between polls, e.g. a clock advance)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred():
                return True
            if step is not None:
                step()
            else:
                time.sleep(0.01)
        return pred()

    def __enter__(self) -> DriverRunner:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


class VirtualShovel:
    """All device emulators of one shovel, fed from one signals table on one clock.

    ``clock`` defaults to a paced :class:`ReplayClock` at recorded speed starting at
    0; capture time ``t`` corresponds to table time ``table.time[0] + t``.
    ``mti`` selects the MTi emulator: ``"serial"``, ``"can"`` or ``None``.
    """

    def __init__(self, table: SignalsTable, installation: Installation | None = None, *,
                 clock: ReplayClock | None = None, mti: str | None = "serial",
                 adc_transport: str = "tcp", laser: bool = True,
                 motor_channels: ChannelMap = MOTOR_CHANNELS,
                 inclinometer_channels: ChannelMap = INCLINOMETER_CHANNELS,
                 laser_interval_us: int = 20000, mti_rate_hz: int = 100,
                 adc_poll_hz: float = 50.0) -> None:
        if mti not in ("serial", "can", None):
            raise ValueError(f"mti must be 'serial', 'can' or None, got {mti!r}")
        self.table = table
        self.installation = installation or Installation()
        self.clock = clock or ReplayClock(0.0, speed=1.0)
        self.mti_kind = mti
        self.laser_interval_us = laser_interval_us
        self.mti_rate_hz = mti_rate_hz
        self.adc_poll_hz = adc_poll_hz
        self.laser = Ar4000Emulator(laser_source(table, self.installation),
                                    clock=self.clock) if laser else None
        self.adc_motors = ModbusAdcEmulator(adc_source(table, motor_channels), motor_channels,
                                            transport=adc_transport, clock=self.clock)
        self.adc_incl = ModbusAdcEmulator(adc_source(table, inclinometer_channels),
                                          inclinometer_channels, transport=adc_transport,
                                          unit=2, clock=self.clock)
        self.mti: Any = None
        self.can_channel: str | None = None
        if mti is not None:
            from hil_fixtures.mti import angles_from_signals

            angles = angles_from_signals(table, self.installation, loop=False)
            if mti == "serial":
                from hil_fixtures.mti import MtiEmulator

                self.mti = MtiEmulator(angles, clock=self.clock, t0=0.0)
            else:
                from hil_fixtures.mti_can import MtiCanEmulator

                self.can_channel = f"vshovel-{uuid.uuid4().hex[:8]}"
                self.mti = MtiCanEmulator(angles, self.can_channel, rate_hz=mti_rate_hz,
                                          clock=self.clock, t0=0.0)

    def start(self) -> VirtualShovel:
        started: list[Any] = []
        try:
            for emu in (self.laser, self.adc_motors, self.adc_incl, self.mti):
                if emu is not None:
                    emu.start()
                    started.append(emu)
        except BaseException:
            for emu in started:
                emu.stop()
            raise
        return self

    def stop(self) -> None:
        for emu in (self.mti, self.adc_incl, self.adc_motors, self.laser):
            if emu is not None:
                try:
                    emu.stop()
                except Exception:  # noqa: BLE001
                    pass

    def __enter__(self) -> VirtualShovel:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def config(self) -> dict[str, Any]:
        """A record/daemon configuration whose devices are these emulators."""
        inst = {k: getattr(self.installation, k) for k in self.installation.__dataclass_fields__}
        devices: dict[str, Any] = {}
        if self.laser is not None:
            devices["laser"] = {"kind": "ar4000", "port": self.laser.port,
                                "sample_interval_us": self.laser_interval_us}
        if self.mti_kind == "serial":
            devices["mti"] = {"kind": "mti_serial", "port": self.mti.port, "baudrate": 115200,
                              "rate_hz": self.mti_rate_hz}
        elif self.mti_kind == "can":
            devices["mti"] = {"kind": "mti_can", "interface": "virtual",
                              "channel": self.can_channel}
        devices["adc_motors"] = self.adc_motors.driver_config(poll_hz=self.adc_poll_hz)
        devices["adc_incl"] = self.adc_incl.driver_config(poll_hz=self.adc_poll_hz)
        return {"installation": inst, "devices": devices}
