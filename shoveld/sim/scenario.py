"""Scenarios for the simulated shovel: dig cycles, truck loading, calibration trials.

A scenario is a list of keyframes (joint positions, payload, phase) joined by
smooth quintic segments; the plant turns it into currents, and ``measure`` adds
the sensor noise and the sampling of the real logger. The truth (payload and
phase times per pass) is returned beside the table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shoveld.cycle.phases import PHASES
from shoveld.signals.table import SignalsTable
from shoveld.sim.plant import Motion, Plant, PlantParams

FINE_HZ = 500.0
"""Internal integration grid of the simulator."""
KNOWN_LOAD_KG = 8420.0
"""The thesis's truck-scale-weighed calibration load."""
RATED_PAYLOAD_KG = 35000.0


def quintic_path(tk: np.ndarray, yk: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Interpolate keyframes with quintic Hermite segments: C2, no overshoot at holds.

    Knot velocities are the harmonic mean of the adjacent slopes (zero at extrema and
    holds, as PCHIP does); knot accelerations are zero.
    """
    h = np.diff(tk)
    s = np.diff(yk) / h
    v = np.zeros_like(yk)
    for k in range(1, len(yk) - 1):
        if s[k - 1] * s[k] > 0:
            w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
            v[k] = (w1 + w2) / (w1 / s[k - 1] + w2 / s[k])
    seg = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(h) - 1)
    tau = np.clip((t - tk[seg]) / h[seg], 0.0, 1.0)
    t3, t4, t5 = tau**3, tau**4, tau**5
    h00 = 1 - 10 * t3 + 15 * t4 - 6 * t5
    h10 = tau - 6 * t3 + 8 * t4 - 3 * t5
    h01 = 10 * t3 - 15 * t4 + 6 * t5
    h11 = -4 * t3 + 7 * t4 - 3 * t5
    return (h00 * yk[seg] + h10 * h[seg] * v[seg] + h01 * yk[seg + 1]
            + h11 * h[seg] * v[seg + 1])


@dataclass
class Timeline:
    """Keyframes of a scenario under construction (degrees and metres)."""

    t: list[float] = field(default_factory=lambda: [0.0])
    th: list[float] = field(default_factory=lambda: [-45.0])
    d: list[float] = field(default_factory=lambda: [6.6])
    swing: list[float] = field(default_factory=lambda: [0.0])
    payload: list[float] = field(default_factory=lambda: [0.0])
    phases: list[tuple[float, float, str]] = field(default_factory=list)
    digs: list[tuple[float, float, float]] = field(default_factory=list)
    """(start, end, peak bank force N) per dig."""

    @property
    def now(self) -> float:
        return self.t[-1]

    def go(self, dt: float, phase: str, th: float | None = None, d: float | None = None,
           swing: float | None = None, payload: float | None = None) -> None:
        """Move to the given positions in ``dt`` seconds (None: hold)."""
        t0 = self.now
        self.t.append(t0 + dt)
        self.th.append(self.th[-1] if th is None else th)
        self.d.append(self.d[-1] if d is None else d)
        self.swing.append(self.swing[-1] if swing is None else swing)
        self.payload.append(self.payload[-1] if payload is None else payload)
        if self.phases and self.phases[-1][2] == phase and self.phases[-1][1] == t0:
            self.phases[-1] = (self.phases[-1][0], t0 + dt, phase)
        else:
            self.phases.append((t0, t0 + dt, phase))


@dataclass
class PassTruth:
    """What really happened in one pass."""

    index: int
    truck: int
    payload_kg: float
    phases: dict[str, tuple[float, float]]
    verified: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"pass": self.index, "truck": self.truck, "payload_kg": self.payload_kg,
                "verified": self.verified, "start_s": self.phases["dig"][0],
                "end_s": self.phases["dump"][1],
                "phases": {k: list(v) for k, v in self.phases.items()}}


def dig_cycle(tl: Timeline, rng: np.random.Generator, payload: float, swing_to: float) -> None:
    """One pass: dig, lift, swing to the truck, dump, return to the bank."""
    dig_t = rng.uniform(6.0, 9.0)
    start = tl.now
    mid_d = rng.uniform(9.0, 10.2)
    tl.go(dig_t * 0.55, "dig", th=rng.uniform(-30, -22), d=mid_d, payload=payload * 0.6)
    tl.go(dig_t * 0.45, "dig", th=rng.uniform(-10, -5), d=mid_d - rng.uniform(0.2, 0.6),
          payload=payload)
    tl.digs.append((start, tl.now, rng.uniform(1.5e5, 4.0e5)))
    tl.go(rng.uniform(2.0, 3.0), "lift", th=rng.uniform(8, 16), d=rng.uniform(8.4, 9.2))
    tl.go(rng.uniform(5.0, 7.0), "swing", th=rng.uniform(18, 28), d=rng.uniform(8.6, 9.8),
          swing=swing_to)
    tl.go(0.3, "dump")
    tl.go(1.0, "dump", payload=0.0)
    tl.go(rng.uniform(0.4, 1.0), "dump")
    tl.go(rng.uniform(5.0, 7.0), "return", th=rng.uniform(-48, -40), d=rng.uniform(6.4, 7.0),
          swing=0.0)


def bank_force(t: np.ndarray, th: np.ndarray, d: np.ndarray,
               digs: list[tuple[float, float, float]], rng: np.random.Generator) -> np.ndarray:
    """Resisting force of the bank during each dig, as generalized forces on (th, d)."""
    out = np.zeros((len(t), 2))
    for t0, t1, peak in digs:
        sel = (t >= t0) & (t <= t1)
        tau = (t[sel] - t0) / (t1 - t0)
        wobble = 1.0 + 0.25 * np.sin(2 * np.pi * tau * rng.uniform(2, 5) + rng.uniform(0, 6))
        f = peak * np.sin(np.pi * tau) ** 2 * wobble
        out[sel, 0] = f * d[sel]
        out[sel, 1] = 0.5 * f
    return out


def motion_from_timeline(tl: Timeline, rng: np.random.Generator, boom_deg: float,
                         fine_hz: float = FINE_HZ) -> Motion:
    tk = np.asarray(tl.t)
    t = np.arange(0.0, tk[-1], 1.0 / fine_hz)
    th = np.radians(quintic_path(tk, np.asarray(tl.th), t))
    d = quintic_path(tk, np.asarray(tl.d), t)
    swing = np.radians(quintic_path(tk, np.asarray(tl.swing), t))
    payload = quintic_path(tk, np.asarray(tl.payload), t)
    phase = np.zeros(len(t), dtype=np.int8)
    for t0, t1, name in tl.phases:
        phase[(t >= t0) & (t < t1)] = PHASES.index(name)
    m = Motion(t=t, th=th, d=d, swing=swing, boom=np.full(len(t), math.radians(boom_deg)),
               payload=payload, phase=phase)
    m.bank_force = bank_force(t, th, d, tl.digs, rng)
    return m


@dataclass
class SensorNoise:
    """Standard deviations of the logged signals (per sample, white)."""

    handle_deg: float = 0.03
    crowd_m: float = 0.002
    swing_deg: float = 0.1
    boom_deg: float = 0.05
    current_a: float = 2.0
    current_rel: float = 0.003
    field_a: float = 0.3
    incl_deg: float = 0.05
    adc_lsb_a: float = 4000.0 / 32768.0

    def scaled(self, k: float) -> SensorNoise:
        return SensorNoise(**{n: v * k if n != "adc_lsb_a" else v
                              for n, v in self.__dict__.items()})


def measure(motion: Motion, ctx: dict[str, Any], rate_hz: float, noise: SensorNoise,
            rng: np.random.Generator, effects: list[Any]) -> dict[str, np.ndarray]:
    """Sample the true signals at the logger's rate and add sensor noise."""
    dt = float(motion.t[1] - motion.t[0])
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    idx = np.arange(0, len(motion.t), step)
    n = len(idx)
    pp: PlantParams = ctx["params"]

    def cur(x: np.ndarray) -> np.ndarray:
        y = x + rng.normal(0, 1, n) * (noise.current_a + noise.current_rel * np.abs(x))
        return np.round(y / noise.adc_lsb_a) * noise.adc_lsb_a

    i_h = ctx["i_h"][idx]
    cols = {
        "time_s": motion.t[idx],
        "handle_deg": np.degrees(motion.th[idx]) + rng.normal(0, noise.handle_deg, n),
        "crowd_m": motion.d[idx] + rng.normal(0, noise.crowd_m, n),
        "swing_deg": np.degrees(motion.swing[idx]) + rng.normal(0, noise.swing_deg, n),
        "boom_deg": np.degrees(motion.boom[idx]) + rng.normal(0, noise.boom_deg, n),
        "hoist1_a": cur(pp.hoist_split * i_h),
        "hoist2_a": cur((1 - pp.hoist_split) * i_h),
        "hoist_field_a": ctx["i_hf"][idx] + rng.normal(0, noise.field_a, n),
        "crowd_a": cur(ctx["i_c"][idx]),
        "crowd_field_a": pp.crowd_field_a + rng.normal(0, noise.field_a, n),
        "swing_a": cur(ctx["i_s"][idx]),
        "swing_field_a": pp.swing_field_a + rng.normal(0, noise.field_a, n),
        "roll_deg": rng.normal(0, noise.incl_deg, n),
        "pitch_deg": rng.normal(0, noise.incl_deg, n),
        "payload_kg": np.full(n, np.nan),
    }
    ctx["sample_index"] = idx
    for e in effects:
        e.measure(cols, ctx, rng)
    return cols


@dataclass
class SimResult:
    table: SignalsTable
    passes: list[PassTruth]
    truth: dict[str, Any]
    motion: Motion
    ctx: dict[str, Any]

    def truth_json(self) -> dict[str, Any]:
        return {**self.truth, "passes": [p.as_dict() for p in self.passes]}


def _finish(tl: Timeline, rng: np.random.Generator, pp: PlantParams, effects: list[Any],
            rate_hz: float, noise: SensorNoise, meta: dict[str, str]) -> tuple[
                SignalsTable, Motion, dict[str, Any]]:
    motion = motion_from_timeline(tl, rng, pp.boom_deg)
    ctx = Plant(pp, effects).run(motion)
    cols = measure(motion, ctx, rate_hz, noise, rng, effects)
    table = SignalsTable.from_arrays(meta={"sample_rate_hz": f"{rate_hz:g}",
                                           "shovel": "sim-ph2100", **meta}, **cols)
    return table, motion, ctx


def simulate_cycles(n_passes: int, seed: int = 0, *, payload_range: tuple[float, float] = (
        3000.0, 35000.0), truck_target_kg: float | None = None, verified_fraction: float = 0.0,
        rate_hz: float = 50.0, params: PlantParams | None = None, effects: list[Any] | None = None,
        noise: SensorNoise | None = None, payloads: list[float] | None = None) -> SimResult:
    """Dig cycles loading trucks.

    With ``truck_target_kg`` the passes of a truck are drawn so the truck fills to about
    the target, and the trucks are separated by an exchange pause; otherwise every pass
    draws its payload from ``payload_range`` and a truck change comes every 4 passes.
    """
    rng = np.random.default_rng(seed)
    pp = params or PlantParams()
    effects = effects or []
    noise = noise or SensorNoise()
    tl = Timeline()
    tl.go(3.0, "idle")
    passes: list[PassTruth] = []
    truck, in_truck, truck_load = 1, 0, 0.0
    for k in range(n_passes):
        if payloads is not None:
            m = float(payloads[k])
        elif truck_target_kg:
            left = truck_target_kg - truck_load
            m = float(np.clip(rng.normal(0.235, 0.025) * truck_target_kg, 3000.0,
                              min(RATED_PAYLOAD_KG, max(left * 1.08, 3000.0))))
        else:
            m = float(rng.uniform(*payload_range))
        before = len(tl.phases)
        dig_cycle(tl, rng, m, swing_to=float(rng.uniform(70, 110)))
        ph: dict[str, tuple[float, float]] = {}
        for t0, t1, name in tl.phases[before:]:
            ph[name] = (t0, t1) if name not in ph else (ph[name][0], t1)
        verified = bool(rng.uniform() < verified_fraction)
        passes.append(PassTruth(k + 1, truck, m, ph, verified))
        in_truck += 1
        truck_load += m
        full = (truck_load >= 0.9 * truck_target_kg) if truck_target_kg else in_truck >= 4
        if full and k < n_passes - 1:
            tl.go(rng.uniform(25.0, 40.0), "idle")
            truck, in_truck, truck_load = truck + 1, 0, 0.0
        else:
            tl.go(rng.uniform(0.5, 2.0), "idle")
    table, motion, ctx = _finish(tl, rng, pp, effects, rate_hz, noise, {})
    t = table.time
    col = table.columns["payload_kg"]
    for p in passes:
        if p.verified:
            col[(t >= p.phases["lift"][0]) & (t < p.phases["dump"][0] + 0.3)] = p.payload_kg
    truth = {"scenario": "cycles", "seed": seed, "params": pp.as_dict(),
             "effects": {e.name: e.magnitude for e in effects},
             "truck_target_kg": truck_target_kg}
    return SimResult(table, passes, truth, motion, ctx)


def simulate_calibration(load_kg: float, seed: int = 0, *, rate_hz: float = 50.0,
                         params: PlantParams | None = None, effects: list[Any] | None = None,
                         noise: SensorNoise | None = None, n_poses: int = 16,
                         free_motion_s: float = 120.0) -> SimResult:
    """A calibration trial with a fixed load: static poses, then free motion in the air."""
    rng = np.random.default_rng(seed)
    pp = params or PlantParams()
    effects = effects or []
    noise = noise or SensorNoise()
    tl = Timeline(th=[-30.0], d=[7.0], payload=[load_kg])
    tl.go(2.0, "idle")
    ths = rng.permutation(np.linspace(-35, 28, n_poses))
    ds = rng.permutation(np.linspace(6.6, 10.4, n_poses))
    for th, d in zip(ths, ds, strict=True):
        tl.go(4.0, "lift", th=float(th), d=float(d))
        tl.go(4.0, "idle")
    end = tl.now + free_motion_s
    while tl.now < end:
        # Bounded steps: a free-falling dipper cannot be driven faster than gravity by a rope.
        th = float(np.clip(tl.th[-1] + rng.uniform(-25, 25), -40, 30))
        d = float(np.clip(tl.d[-1] + rng.uniform(-1.8, 1.8), 6.5, 10.5))
        tl.go(float(rng.uniform(2.5, 4.5)), "lift", th=th, d=d)
    tl.go(2.0, "idle")
    table, motion, ctx = _finish(tl, rng, pp, effects, rate_hz, noise,
                                 {"known_payload_kg": f"{load_kg:g}"})
    table.columns["payload_kg"][:] = load_kg
    truth = {"scenario": "calibration", "seed": seed, "load_kg": load_kg,
             "params": pp.as_dict(), "effects": {e.name: e.magnitude for e in effects}}
    return SimResult(table, [], truth, motion, ctx)
