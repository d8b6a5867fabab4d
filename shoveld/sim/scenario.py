"""Scenarios for the simulated shovel: dig cycles, truck loading, calibration trials.

A scenario is a list of keyframes (joint positions, payload, phase) joined by
smooth quintic segments; the plant turns it into currents, and ``measure`` adds
the sensor noise and the sampling of the real logger. The truth (payload and
phase times per pass) is returned beside the table.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shoveld.cycle.phases import PHASES
from shoveld.signals.table import SignalsTable
from shoveld.sim.machine import Channel, Installation, Machine, slow_wave, wave_phases
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
    crb_kg: float = math.nan
    """Cramer-Rao bound of the payload from this pass's lift and swing currents."""

    def as_dict(self) -> dict[str, Any]:
        return {"pass": self.index, "truck": self.truck, "payload_kg": self.payload_kg,
                "verified": self.verified, "crb_kg": self.crb_kg, "start_s": self.phases["dig"][0],
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
    """Standard deviations of the logged signals (per sample, white): the ideal machine's
    sensors. A realistic machine's are in ``shoveld.sim.machine.Installation``."""

    handle_deg: float = 0.03
    crowd_m: float = 0.002
    swing_deg: float = 0.1
    boom_deg: float = 0.05
    current_a: float = 2.0
    current_rel: float = 0.003
    field_a: float = 0.3
    incl_deg: float = 0.05

    def scaled(self, k: float) -> SensorNoise:
        return SensorNoise(**{n: v * k for n, v in self.__dict__.items()})

    def installation(self, base: Installation | None = None) -> Installation:
        """``base`` (default: unbiased 16-bit sensors) with these noise levels."""
        from dataclasses import replace

        b = base or Installation()

        def arm(c: Channel) -> Channel:
            return replace(c, noise_a=self.current_a, noise_rel=self.current_rel)

        def fld(c: Channel) -> Channel:
            return replace(c, noise_a=self.field_a, noise_rel=0.0)

        return replace(b, hoist1=arm(b.hoist1), hoist2=arm(b.hoist2), crowd=arm(b.crowd),
                       swing=arm(b.swing), hoist_field=fld(b.hoist_field),
                       crowd_field=fld(b.crowd_field), swing_field=fld(b.swing_field),
                       handle_deg=self.handle_deg, crowd_m=self.crowd_m,
                       swing_deg=self.swing_deg, boom_deg=self.boom_deg, incl_deg=self.incl_deg)


DEFAULT_MACHINE_SEED = 0
"""The machine ``simulate_*`` use when given none: a realistic one."""


def resolve_machine(machine: Machine | None, params: PlantParams | None,
                    noise: SensorNoise | None) -> Machine:
    """The machine to simulate: the given one; else the ideal one when plant parameters
    or a noise level are given (the old interface); else the default realistic one."""
    from dataclasses import replace

    if machine is None:
        machine = Machine.ideal() if (params or noise) else Machine.draw(DEFAULT_MACHINE_SEED)
    if params is not None:
        machine = replace(machine, plant=params)
    if noise is not None:
        machine = replace(machine, sensors=noise.installation(
            machine.sensors if machine.realistic else None))
    return machine


def measure(motion: Motion, ctx: dict[str, Any], rate_hz: float, machine: Machine,
            rng: np.random.Generator, effects: list[Any], t_offset: float = 0.0,
            waves: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Sample the true signals at the logger's rate, through the machine's sensors.

    ``t_offset`` is the segment's start in the run, ``waves`` the phases of the run's
    slow wanders (drawn here for the first segment, and kept in ``ctx["waves"]``)."""
    dt = float(motion.t[1] - motion.t[0])
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    idx = np.arange(0, len(motion.t), step)
    n = len(idx)
    pp = machine.plant
    s = machine.sensors
    t = motion.t[idx]
    if waves is None:
        waves = {}
        for name, amp in (("split", s.split_wander), ("drift", s.handle_drift_deg)):
            if amp != 0.0:  # (a flat wave draws nothing)
                waves[name] = wave_phases(rng)
    ctx["waves"] = waves
    split = s.split + slow_wave(t + t_offset, s.split_wander, s.split_period_s, rng,
                                waves.get("split"))
    drift = slow_wave(t + t_offset, s.handle_drift_deg, s.drift_period_s, rng,
                      waves.get("drift"))
    i_h = ctx["i_h"][idx]
    ones = np.ones(n)
    cols = {
        "time_s": t + t_offset,
        "handle_deg": np.degrees(motion.th[idx]) + drift + rng.normal(0, s.handle_deg, n),
        "crowd_m": motion.d[idx] + rng.normal(0, s.crowd_m, n),
        "swing_deg": np.degrees(motion.swing[idx]) + rng.normal(0, s.swing_deg, n),
        "boom_deg": np.degrees(motion.boom[idx]) + rng.normal(0, s.boom_deg, n),
        "hoist1_a": s.hoist1.read(split * i_h, rng),
        "hoist2_a": s.hoist2.read((1 - split) * i_h, rng),
        "hoist_field_a": s.hoist_field.read(ctx["i_hf"][idx], rng),
        "crowd_a": s.crowd.read(ctx["i_c"][idx], rng),
        "crowd_field_a": s.crowd_field.read(pp.crowd_field_a * ones, rng),
        "swing_a": s.swing.read(ctx["i_s"][idx], rng),
        "swing_field_a": s.swing_field.read(pp.swing_field_a * ones, rng),
        "roll_deg": rng.normal(0, s.incl_deg, n),
        "pitch_deg": rng.normal(0, s.incl_deg, n),
        "payload_kg": np.full(n, np.nan),
    }
    ctx["sample_index"] = idx
    ctx["split"] = split
    for e in effects:
        e.measure(cols, ctx, rng)
    return cols


def payload_information(ctx: dict[str, Any], machine: Machine, t0: float, t1: float) -> float:
    """Fisher information (1/kg^2) of the payload in the logged currents between t0 and t1.

    From the current-noise model alone, channels as measured: the sensitivity of each
    logged current to the payload (the plant's virtual work per kilogram, through the
    channel's gain) over that channel's noise at the sample's reading. The Cramer-Rao
    bound of an unbiased payload estimate from those samples is 1 / sqrt(information).
    """
    idx = ctx["sample_index"]
    t = ctx["motion"].t[idx]
    sel = (t >= t0) & (t <= t1)
    if "di_h_dm" not in ctx or not sel.any():
        return 0.0
    s = machine.sensors
    j = idx[sel]
    split = ctx["split"][sel]
    i_h, i_c = ctx["i_h"][j], ctx["i_c"][j]
    g_h = split * (1 + s.hoist1.gain) + (1 - split) * (1 + s.hoist2.gain)
    var_h = s.hoist1.sigma(split * i_h) ** 2 + s.hoist2.sigma((1 - split) * i_h) ** 2
    var_c = s.crowd.sigma(i_c) ** 2
    dh = ctx["di_h_dm"][j] * g_h
    dc = ctx["di_c_dm"][j] * (1 + s.crowd.gain)
    return float(np.sum(dh * dh / var_h) + np.sum(dc * dc / var_c))


@dataclass
class SimResult:
    table: SignalsTable
    passes: list[PassTruth]
    truth: dict[str, Any]
    motion: Motion | None
    """The true motion and the plant's context (None for a run simulated in several
    segments: see :func:`iter_cycles`)."""
    ctx: dict[str, Any] | None

    def truth_json(self) -> dict[str, Any]:
        return {**self.truth, "passes": [p.as_dict() for p in self.passes]}


def _finish(tl: Timeline, rng: np.random.Generator, machine: Machine, effects: list[Any],
            rate_hz: float, meta: dict[str, str], t_offset: float = 0.0,
            waves: dict[str, np.ndarray] | None = None
            ) -> tuple[SignalsTable, Motion, dict[str, Any]]:
    pp = machine.plant
    motion = motion_from_timeline(tl, rng, pp.boom_deg)
    ctx = Plant(pp, effects, machine.drive).run(motion)
    cols = measure(motion, ctx, rate_hz, machine, rng, effects, t_offset, waves)
    name = "sim-ph2100" if not machine.realistic else f"sim-ph2100-m{machine.seed}"
    table = SignalsTable.from_arrays(meta={"sample_rate_hz": f"{rate_hz:g}",
                                           "shovel": name, **meta}, **cols)
    return table, motion, ctx


CHUNK_PASSES = 32
"""Passes simulated at once: a longer run is simulated and written truck by truck in
segments of about this many passes, so its memory does not grow with its length."""


def simulate_cycles(n_passes: int, seed: int = 0, **kw: Any) -> SimResult:
    """Dig cycles loading trucks, as one table (see :func:`iter_cycles`).

    With ``truck_target_kg`` the passes of a truck are drawn so the truck fills to about
    the target, and the trucks are separated by an exchange pause; otherwise every pass
    draws its payload from ``payload_range`` and a truck change comes every 4 passes.
    """
    parts = list(iter_cycles(n_passes, seed, **kw))
    if len(parts) == 1:
        return parts[0]
    cols = {n: np.concatenate([p.table.columns[n] for p in parts])
            for n in parts[0].table.columns}
    table = SignalsTable.from_arrays(meta=dict(parts[0].table.meta), **cols)
    return SimResult(table, [q for p in parts for q in p.passes], parts[0].truth, None, None)


def iter_cycles(n_passes: int, seed: int = 0, *, payload_range: tuple[float, float] = (
        3000.0, 35000.0), truck_target_kg: float | None = None, verified_fraction: float = 0.0,
        rate_hz: float = 50.0, params: PlantParams | None = None, effects: list[Any] | None = None,
        noise: SensorNoise | None = None, payloads: list[float] | None = None,
        machine: Machine | None = None, chunk_passes: int = CHUNK_PASSES
        ) -> Iterator[SimResult]:
    """Dig cycles in segments of whole trucks, each about ``chunk_passes`` passes long.

    A segment ends in a truck exchange (the dipper at rest, the field settled), and the
    next starts from that pose at that time, with the run's sensors and their slow
    wanders going on continuously; its noise comes from its own stream (seed, segment).
    A run of at most ``chunk_passes`` passes is one segment.
    """
    machine = resolve_machine(machine, params, noise)
    effects = effects or []
    truck, in_truck, truck_load = 1, 0, 0.0
    t_offset = 0.0
    waves: dict[str, np.ndarray] | None = None
    k = 0
    segment = 0
    last = (-45.0, 6.6, 0.0)
    """Where the previous segment left the dipper (handle, crowd, swing)."""
    while k < n_passes or segment == 0:
        rng = np.random.default_rng(seed if segment == 0 else [seed, segment])
        tl = Timeline(th=[last[0]], d=[last[1]], swing=[last[2]])
        if segment == 0:
            tl.go(3.0, "idle")
        passes: list[PassTruth] = []
        while k < n_passes:
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
            k += 1
            full = (truck_load >= 0.9 * truck_target_kg) if truck_target_kg else in_truck >= 4
            if full and k < n_passes:
                tl.go(rng.uniform(25.0, 40.0), "idle")
                truck, in_truck, truck_load = truck + 1, 0, 0.0
                if len(passes) >= chunk_passes:
                    break
            else:
                tl.go(rng.uniform(0.5, 2.0), "idle")
        table, motion, ctx = _finish(tl, rng, machine, effects, rate_hz, {}, t_offset, waves)
        waves = ctx["waves"]
        t = table.time
        col = table.columns["payload_kg"]
        for p in passes:
            if p.verified:
                col[(t >= p.phases["lift"][0] + t_offset)
                    & (t < p.phases["dump"][0] + 0.3 + t_offset)] = p.payload_kg
            info = payload_information(ctx, machine, p.phases["lift"][0] + 0.4,
                                       p.phases["swing"][1])
            p.crb_kg = 1.0 / math.sqrt(info) if info > 0 else math.inf
            p.phases = {n: (a + t_offset, b + t_offset) for n, (a, b) in p.phases.items()}
        truth = {"scenario": "cycles", "seed": seed, "params": machine.plant.as_dict(),
                 "machine": machine.describe(),
                 "effects": {e.name: e.magnitude for e in effects},
                 "truck_target_kg": truck_target_kg}
        yield SimResult(table, passes, truth, motion, ctx)
        last = (tl.th[-1], tl.d[-1], tl.swing[-1])
        # The next segment's first sample follows this one's last by one logger period.
        t_offset = float(t[-1]) + 1.0 / rate_hz
        segment += 1


def simulate_calibration(load_kg: float, seed: int = 0, *, rate_hz: float = 50.0,
                         params: PlantParams | None = None, effects: list[Any] | None = None,
                         noise: SensorNoise | None = None, n_poses: int = 16,
                         free_motion_s: float = 120.0, fast_moves: int | None = None,
                         machine: Machine | None = None) -> SimResult:
    """A calibration trial with a fixed load: held poses, free motion in the air, then
    fast hoisting and lowering strokes (on a machine that weakens its field, they sweep
    the hoist field so that its pull per ampere can be identified over the range
    operation uses)."""
    rng = np.random.default_rng(seed)
    machine = resolve_machine(machine, params, noise)
    pp = machine.plant
    effects = effects or []
    if fast_moves is None:
        fast_moves = 8 if machine.drive is not None else 0
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
    for _ in range(fast_moves):
        d = float(rng.uniform(7.5, 10.0))
        tl.go(float(rng.uniform(2.4, 3.2)), "lift", th=-36.0, d=d)
        tl.go(1.0, "idle")
        tl.go(float(rng.uniform(3.0, 4.0)), "lift", th=float(rng.uniform(2.0, 8.0)))
        tl.go(1.0, "idle")
    tl.go(2.0, "idle")
    table, motion, ctx = _finish(tl, rng, machine, effects, rate_hz,
                                 {"known_payload_kg": f"{load_kg:g}"})
    table.columns["payload_kg"][:] = load_kg
    truth = {"scenario": "calibration", "seed": seed, "load_kg": load_kg,
             "params": pp.as_dict(), "machine": machine.describe(),
             "effects": {e.name: e.magnitude for e in effects}}
    return SimResult(table, [], truth, motion, ctx)
