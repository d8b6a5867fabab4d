"""One simulated machine as it is installed: its drive, its sensors and their faults.

A model that ignores what real sensors and drives do fits only a simulator
(``model-notes.md``, last section). This module gives the simulated shovel those
imperfections, written from the transducers' and the drive's physics and never
next to the model term that will later have to cope with them:

* Hall-effect current transducers with a zero offset and a gain error that belong
  to the installation, noise that grows with the reading, and a 12-bit logger ADC;
* the two hoist motors on separate converters, sharing the pull unevenly and with
  a wandering split;
* the handle-angle sensor drifting slowly by tenths of a degree;
* a DC hoist drive that weakens its field above base speed in both directions
  (constant-power region: flux ~ base speed / speed), the pull per ampere following
  the motor's magnetisation curve (a Froehlich curve here, not the plant's tanh).

A seed draws a whole machine (its mechanical parameters too), so a bench over
seeds is a bench over machines. Every file simulated with one ``Machine`` shares
its offsets and gains, as the files of one installation do.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from shoveld.sim.plant import PlantParams

if TYPE_CHECKING:
    from shoveld.model.params import ModelParams

CURRENT_FULL_SCALE_A = 4000.0
"""Range of the armature current transducers (thesis: 4000 A Hall sensors)."""
FIELD_FULL_SCALE_A = 200.0
"""Range of the field current transducers."""


@dataclass(frozen=True)
class Channel:
    """One Hall-effect transducer and its logger channel."""

    offset_a: float = 0.0
    gain: float = 0.0
    """Relative gain error: the reading is (1 + gain) times the current."""
    noise_a: float = 2.0
    noise_rel: float = 0.003
    full_scale_a: float = CURRENT_FULL_SCALE_A
    bits: int = 16

    @property
    def lsb_a(self) -> float:
        return 2.0 * self.full_scale_a / 2**self.bits

    def sigma(self, x: np.ndarray) -> np.ndarray:
        """Per-sample standard deviation of the reading of current ``x`` (noise and
        quantisation)."""
        return np.sqrt(self.noise_a**2 + (self.noise_rel * x) ** 2 + self.lsb_a**2 / 12.0)

    def read(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the logger records for the true current ``x``."""
        y = (1.0 + self.gain) * x + self.offset_a
        y = y + rng.normal(0.0, 1.0, len(x)) * np.hypot(self.noise_a, self.noise_rel * x)
        lsb = self.lsb_a
        y = np.round(y / lsb) * lsb
        return np.clip(y, -self.full_scale_a, self.full_scale_a - lsb)


@dataclass(frozen=True)
class Installation:
    """The sensors of one machine."""

    hoist1: Channel = Channel()
    hoist2: Channel = Channel()
    crowd: Channel = Channel()
    swing: Channel = Channel()
    hoist_field: Channel = Channel(noise_a=0.3, noise_rel=0.0, full_scale_a=FIELD_FULL_SCALE_A)
    crowd_field: Channel = Channel(noise_a=0.3, noise_rel=0.0, full_scale_a=FIELD_FULL_SCALE_A)
    swing_field: Channel = Channel(noise_a=0.3, noise_rel=0.0, full_scale_a=FIELD_FULL_SCALE_A)
    split: float = 0.51
    """Share of the rope pull carried by hoist motor 1, on average."""
    split_wander: float = 0.0
    """Amplitude of the slow wander of that share (converters drifting apart)."""
    split_period_s: float = 90.0
    handle_drift_deg: float = 0.0
    """Amplitude of the slow drift of the handle-angle sensor."""
    drift_period_s: float = 600.0
    handle_deg: float = 0.03
    crowd_m: float = 0.002
    swing_deg: float = 0.1
    boom_deg: float = 0.05
    incl_deg: float = 0.05

    @classmethod
    def draw(cls, rng: np.random.Generator) -> Installation:
        """A plausible installation: offsets up to +-5 A, gain errors of a few tenths of a
        percent, noise 2-4 A + 0.1-0.3 % of the reading, a 12-bit ADC over +-4000 A."""

        def arm() -> Channel:
            return Channel(offset_a=float(rng.uniform(-5, 5)), gain=float(rng.normal(0, 0.003)),
                           noise_a=float(rng.uniform(2, 4)),
                           noise_rel=float(rng.uniform(0.001, 0.003)), bits=12)

        def fld() -> Channel:
            return Channel(offset_a=float(rng.uniform(-0.5, 0.5)),
                           gain=float(rng.normal(0, 0.003)), noise_a=float(rng.uniform(0.2, 0.4)),
                           noise_rel=0.0, full_scale_a=FIELD_FULL_SCALE_A, bits=12)

        return cls(hoist1=arm(), hoist2=arm(), crowd=arm(), swing=arm(), hoist_field=fld(),
                   crowd_field=fld(), swing_field=fld(),
                   split=float(0.5 + rng.uniform(-0.01, 0.01)),
                   split_wander=float(rng.uniform(0.005, 0.01)),
                   split_period_s=float(rng.uniform(40, 200)),
                   handle_drift_deg=float(rng.uniform(0.05, 0.12)),
                   drift_period_s=float(rng.uniform(300, 1200)))

    def scaled(self, k: float) -> Installation:
        """Every noise times ``k`` (offsets, gains and drift unchanged)."""

        def ch(c: Channel) -> Channel:
            return replace(c, noise_a=c.noise_a * k, noise_rel=c.noise_rel * k)

        return replace(self, hoist1=ch(self.hoist1), hoist2=ch(self.hoist2), crowd=ch(self.crowd),
                       swing=ch(self.swing), hoist_field=ch(self.hoist_field),
                       crowd_field=ch(self.crowd_field), swing_field=ch(self.swing_field),
                       handle_deg=self.handle_deg * k, crowd_m=self.crowd_m * k,
                       swing_deg=self.swing_deg * k, boom_deg=self.boom_deg * k,
                       incl_deg=self.incl_deg * k)


@dataclass(frozen=True)
class FieldDrive:
    """A DC hoist drive that weakens the field above base speed, both ways.

    Above base speed the armature voltage is at its limit, so the drive lowers the
    flux in proportion to 1 / speed (constant power), down to a minimum field. The
    field winding lags its setpoint; the pull per ampere follows the flux along a
    Froehlich magnetisation curve, flux ~ i_f / (knee + i_f).
    """

    nominal_a: float = 70.0
    min_a: float = 30.0
    hoist_base_m_s: float = 1.7
    lower_base_m_s: float = 0.9
    knee_a: float = 40.0
    tau_s: float = 0.25

    def flux_ratio(self, i_f: np.ndarray) -> np.ndarray:
        """Pull per ampere at field ``i_f`` relative to the nominal field."""
        k = self.knee_a
        i_f = np.maximum(i_f, 0.0)
        return (i_f / (k + i_f)) / (self.nominal_a / (k + self.nominal_a))

    def field_for(self, flux: np.ndarray) -> np.ndarray:
        """Field current giving relative flux ``flux`` (inverse of ``flux_ratio``)."""
        phi = flux * self.nominal_a / (self.knee_a + self.nominal_a)
        return self.knee_a * phi / (1.0 - phi)

    def field_target(self, rope_speed: np.ndarray) -> np.ndarray:
        """Field setpoint for the rope speed (m/s, > 0 paying out, i.e. lowering)."""
        base = np.where(rope_speed > 0, self.lower_base_m_s, self.hoist_base_m_s)
        flux = np.minimum(1.0, base / np.maximum(np.abs(rope_speed), 1e-6))
        i_f = self.field_for(flux)
        return np.clip(i_f, self.min_a, self.nominal_a)

    @classmethod
    def draw(cls, rng: np.random.Generator) -> FieldDrive:
        return cls(hoist_base_m_s=float(rng.uniform(1.5, 2.0)),
                   lower_base_m_s=float(rng.uniform(0.7, 1.1)),
                   knee_a=float(rng.uniform(30, 55)), tau_s=float(rng.uniform(0.15, 0.35)))


@dataclass(frozen=True)
class Machine:
    """A simulated shovel as installed: mechanics, drive and sensors."""

    plant: PlantParams = field(default_factory=PlantParams)
    sensors: Installation = field(default_factory=Installation)
    drive: FieldDrive | None = None
    """None: the thesis's two-level hoist field (70 A hoisting, 30 A lowering)."""
    seed: int | None = None
    """The machine seed it was drawn from (None: the ideal machine)."""

    @classmethod
    def ideal(cls) -> Machine:
        """The simulator as it was: thesis values, unbiased 16-bit sensors, no drift, the
        two-level field."""
        return cls()

    @classmethod
    def draw(cls, seed: int) -> Machine:
        """A realistic machine: mechanics within a few percent of the thesis's, its own
        installation and drive."""
        rng = np.random.default_rng([seed, 0x5A17])
        base = PlantParams()

        def near(v: float, rel: float) -> float:
            return float(v * (1.0 + rng.uniform(-rel, rel)))

        plant = replace(base, Md=near(base.Md, 0.05), Lc=near(base.Lc, 0.05),
                        Izz=near(base.Izz, 0.15), K_H=near(base.K_H, 0.05),
                        K_C=near(base.K_C, 0.05), fv3=near(base.fv3, 0.2),
                        fc3=near(base.fc3, 0.2), fv4=near(base.fv4, 0.2),
                        fc4=near(base.fc4, 0.2))
        return cls(plant=plant, sensors=Installation.draw(rng), drive=FieldDrive.draw(rng),
                   seed=seed)

    @property
    def realistic(self) -> bool:
        return self.seed is not None

    def flux_ratio(self, i_f: np.ndarray) -> np.ndarray:
        return (self.drive.flux_ratio(i_f) if self.drive is not None
                else self.plant.flux_ratio(i_f))

    def hoist_gain(self) -> float:
        """Mean relative gain of the measured hoist current sum."""
        s = self.sensors
        return s.split * (1 + s.hoist1.gain) + (1 - s.split) * (1 + s.hoist2.gain)

    def identified_truth(self) -> dict[str, float]:
        """The values an identification from this machine's *measured* currents should
        find: force constants per measured ampere, offsets of the measured currents."""
        pp, s = self.plant, self.sensors
        gh = self.hoist_gain()
        return {"Md": pp.Md, "MdLc": pp.Md * pp.Lc, "J": pp.Izz + pp.Md * pp.Lc**2,
                "K_H": pp.K_H * self._measured_flux(70.0) / gh,
                "K_C": pp.K_C / (1 + s.crowd.gain), "fv3": pp.fv3, "fc3": pp.fc3,
                "fv4": pp.fv4, "fc4": pp.fc4,
                "i_H0": s.hoist1.offset_a + s.hoist2.offset_a, "i_C0": s.crowd.offset_a}

    def truth_for(self, params: ModelParams) -> dict[str, float]:
        """True values of the parameters ``params`` names (:meth:`identified_truth`, with
        K_H at the params' nominal field and each field knot at its own field current),
        to hold an identification from this machine's data against."""
        from shoveld.model.terms import field_knot_a

        tr = self.identified_truth()
        out = {}
        for n in params.names:
            knot = field_knot_a(n)
            out[n] = (self.k_h_nominal(params) if n == "K_H" else
                      self.k_h_at(knot) if knot is not None else tr[n])
        return out

    def k_h_nominal(self, params: ModelParams) -> float:
        """True pull per measured ampere at the nominal field of ``params``' hoist drive
        (its K_H's)."""
        return self.k_h_at(float(params.hyper.get("hoist_drive", {}).get("field_nominal_a",
                                                                          70.0)))

    def k_h_at(self, field_measured_a: float) -> float:
        """True pull per measured ampere at a *measured* hoist field current."""
        return self.plant.K_H * self._measured_flux(field_measured_a) / self.hoist_gain()

    def _measured_flux(self, field_measured_a: float) -> float:
        f = self.sensors.hoist_field
        true_field = (field_measured_a - f.offset_a) / (1 + f.gain)
        return float(self.flux_ratio(np.array([true_field]))[0])

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {"seed": self.seed, "realistic": self.realistic,
                             "plant": self.plant.as_dict(),
                             "sensors": asdict(self.sensors),
                             "drive": asdict(self.drive) if self.drive else None}
        d["identified_truth"] = self.identified_truth()
        return d


def wave_phases(rng: np.random.Generator) -> np.ndarray:
    """The random phases of one :func:`slow_wave` (drawn once per run, so a run simulated
    in segments wanders continuously across them)."""
    return np.array([rng.uniform(0, 2 * math.pi) for _ in range(3)])


def slow_wave(t: np.ndarray, amplitude: float, period_s: float, rng: np.random.Generator,
              phases: np.ndarray | None = None) -> np.ndarray:
    """A smooth random wander of about ``amplitude`` over ``period_s``: three sines of
    random phase at the period and two shorter ones, scaled to the amplitude's RMS.
    ``phases`` (from :func:`wave_phases`) fixes them; otherwise they are drawn from
    ``rng``."""
    if amplitude == 0.0:
        return np.zeros_like(t)
    if phases is None:
        phases = wave_phases(rng)
    out = np.zeros_like(t)
    for (k, w), ph in zip(((1.0, 1.0), (2.3, 0.5), (4.1, 0.25)), phases, strict=True):
        out += w * np.sin(2 * math.pi * k * t / period_s + ph)
    return amplitude * out / math.sqrt(0.5 * (1 + 0.25 + 0.0625))
