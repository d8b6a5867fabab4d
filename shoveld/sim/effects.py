"""Physical effects the simulator can switch on, each with a magnitude.

An effect changes the simulated world, never the model: it adds a body, a force,
a friction law, a drive characteristic or a sensor fault through the hook points
of :class:`shoveld.sim.plant.Plant` and :func:`shoveld.sim.scenario.measure`.
The model-side term that tries to explain it lives in ``shoveld.model`` and is
written independently (see ``docs/diagnosis.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

if TYPE_CHECKING:  # (the plant is imported where it is used)
    from shoveld.sim.plant import Position

SIM_EFFECTS: dict[str, type[SimEffect]] = {}


def register_effect(cls: type[SimEffect]) -> type[SimEffect]:
    if cls.name in SIM_EFFECTS:
        raise ValueError(f"sim effect {cls.name!r} registered twice")
    SIM_EFFECTS[cls.name] = cls
    return cls


class SimEffect:
    """Base class: every hook defaults to "no change"."""

    name: ClassVar[str]
    default_magnitude: ClassVar[float] = 1.0
    magnitude_unit: ClassVar[str] = ""
    description: ClassVar[str] = ""
    typical_range: ClassVar[tuple[float, float]] = (0.0, 0.0)
    """Magnitudes the tests and bench/diagnose_matrix.py draw from: physically plausible
    and large enough to matter for the payload (below it the diagnosis may, honestly,
    find nothing; see docs/diagnosis.md for the detection limits)."""

    forms: ClassVar[tuple[str, ...]] = ("",)
    """The physical forms the effect can take. The first is the simple one the tests
    hide; the bench hides the last (``make_effects(form="bench")``), written another
    way, so that a model term is shown to find the physics and not its twin."""

    def __init__(self, magnitude: float | None = None, form: str | None = None) -> None:
        self.magnitude = self.default_magnitude if magnitude is None else float(magnitude)
        self.form = self.forms[0] if form is None else form
        if self.form not in self.forms:
            raise ValueError(f"sim effect {self.name!r} has no form {form!r}; "
                             f"known: {self.forms}")

    def before_dynamics(self, ctx: dict[str, Any]) -> None:
        """May set ctx['boom_true'] or ctx['gravity'] ((N,2) or (2,)) before dynamics."""

    def bodies(self, ctx: dict[str, Any]) -> None:
        """May add or replace entries of ctx['bodies']."""

    def extra_forces(self, ctx: dict[str, Any]) -> np.ndarray:
        """(N, 2) generalized forces the actuators must supply in addition."""
        return 0.0  # type: ignore[return-value]

    def friction(self, ctx: dict[str, Any], fric: np.ndarray) -> np.ndarray:
        return fric

    def before_currents(self, ctx: dict[str, Any]) -> None:
        """May change ctx['i_hf'] (hoist field) or the required forces."""

    def currents(self, ctx: dict[str, Any]) -> None:
        """May change ctx['i_h'], ctx['i_c'] (drive characteristics)."""

    def measure(self, cols: dict[str, np.ndarray], ctx: dict[str, Any],
                rng: np.random.Generator) -> None:
        """May change the measured columns (sensor effects), in place."""


def make_effects(spec: Mapping[str, float | None], form: str = "test") -> list[SimEffect]:
    """Effects from {name: magnitude or None for the default}; ``form`` "test" takes each
    effect's simple form, "bench" its other one (see ``SimEffect.forms``)."""
    unknown = [n for n in spec if n not in SIM_EFFECTS]
    if unknown:
        raise ValueError(f"unknown sim effect(s) {unknown}; known: {sorted(SIM_EFFECTS)}")
    if form not in ("test", "bench"):
        raise ValueError(f"form must be 'test' or 'bench', not {form!r}")
    out = []
    for n, m in spec.items():
        cls = SIM_EFFECTS[n]
        out.append(cls(m, cls.forms[0] if form == "test" else cls.forms[-1]))
    return out


# ---------------------------------------------------------------------------------------
# The effects. Each is written from the mechanics or the drive/sensor physics, in the
# simulator's own Cartesian terms; none calls the model's closed forms.
# ---------------------------------------------------------------------------------------

DRUM_XY = np.array([-6.5, -5.5])
"""Hoist drum (where the rope is wound), in the arm plane relative to the shipper shaft, m."""
BOOM_FOOT_BELOW_SHAFT_M = 6.0
"""Boom foot pin, measured down the boom line from the shipper shaft, m."""


def _sheave(boom: np.ndarray, l_bs: float) -> np.ndarray:
    return l_bs * np.stack([np.cos(boom), np.sin(boom)], axis=-1)


def _bail(th: np.ndarray, d: np.ndarray) -> np.ndarray:
    return d[:, None] * np.stack([np.cos(th), np.sin(th)], axis=-1)


def _fine_to_samples(ctx: dict[str, Any], x: np.ndarray) -> np.ndarray:
    return x[ctx["sample_index"]]


@register_effect
class FieldWeakeningEffect(SimEffect):
    """The hoisting field is not held at 70 A: the drive forces it while the hoist
    accelerates.

    To get more pull per ampere when it has to speed the dipper up, the hoist drive
    raises the field setpoint with the hoist's acceleration: 70 A + M x (rope
    acceleration / 0.5 m/s^2), up to 70 A + M, back to 70 A at constant speed; a
    negative M weakens the field instead. Lowering stays at 30 A. The field winding's
    lag and the plant's magnetisation curve (flux ~ tanh(i_f / knee)) turn this into a
    pull per ampere that changes during every lift, while the base model assumes the
    70 A value.
    """

    name = "hoist_field_weakening"
    default_magnitude = 16.0
    magnitude_unit = "A (field forcing at 0.5 m/s^2 of hoist acceleration)"
    description = "hoist field forced while the hoist accelerates"
    typical_range = (12.0, 20.0)
    ref_acc = 0.5

    def before_currents(self, ctx: dict[str, Any]) -> None:
        from shoveld.sim.plant import derivative, first_order_lag, rope_length

        pp, m, dt = ctx["params"], ctx["motion"], ctx["dt"]
        boom = ctx.get("boom_true", m.boom)
        lr = derivative(rope_length(m.th, m.d, boom, pp.l_bs), dt)
        acc_in = -derivative(lr, dt)
        forcing = np.clip(acc_in / self.ref_acc, 0.0, 1.0)
        hoisting = pp.hoist_field_hoisting_a + self.magnitude * forcing
        target = np.where(lr > 0.02, pp.hoist_field_lowering_a, hoisting)
        ctx["i_hf"] = first_order_lag(target, dt, pp.hoist_field_tau_s)


@register_effect
class SwingCentrifugalEffect(SimEffect):
    """The arm plane turns about the swing axis: the bodies move in 3D.

    Every body of the arm (the arm as a slender dumbbell with its inertia, the
    payload, any rope elements) is placed in 3D at horizontal radius R0 + x from the
    swing axis, its acceleration taken by differentiating the 3D positions on the
    fine grid, and the generalized forces on (th, d) follow by virtual work with
    numerical Jacobians. The difference to the same computation in the plane is what
    the swing adds. Magnitude: R0, the swing axis to shipper shaft radius.
    """

    name = "swing_centrifugal"
    default_magnitude = 4.5
    magnitude_unit = "m (swing axis to shipper shaft)"
    description = "arm plane rotating during swing (3D virtual work)"
    typical_range = (2.5, 6.5)

    @staticmethod
    def _points(bodies: list[Any], th: np.ndarray) -> list[tuple[Any, Any]]:
        """(mass, position function) of point masses equivalent to the bodies."""
        pts: list[tuple[Any, Any]] = []
        for b in bodies:
            m = b.mass
            if not b.inertia:
                pts.append((m, b.position))
                continue
            delta = float(np.sqrt(b.inertia / np.mean(m)))
            for sgn in (-1.0, 1.0):
                def pos(t_: np.ndarray, d_: np.ndarray, bo_: np.ndarray,
                        f: Position = b.position, s: float = sgn * delta) -> np.ndarray:
                    return f(t_, d_, bo_) + s * np.stack([np.cos(t_), np.sin(t_)], axis=-1)
                pts.append((np.asarray(m) * 0.5, pos))
        return pts

    def extra_forces(self, ctx: dict[str, Any]) -> np.ndarray:
        from shoveld.sim.plant import derivative

        m = ctx["motion"]
        dt = ctx["dt"]
        th, d = m.th, m.d
        boom = ctx.get("boom_true", m.boom)
        psi = m.swing
        cps, sps = np.cos(psi), np.sin(psi)
        r0 = self.magnitude
        eps = 1e-6
        q = np.zeros((len(th), 2))
        for mass, pos in self._points(ctx["bodies"], th):
            mass = np.asarray(mass, dtype=float)
            mass = mass[:, None] if mass.ndim else mass

            def p3(t_: np.ndarray, d_: np.ndarray, f: Position = pos) -> np.ndarray:
                xy = f(t_, d_, boom)
                rad = r0 + xy[:, 0]
                return np.stack([rad * cps, xy[:, 1], rad * sps], axis=-1)

            def p2(t_: np.ndarray, d_: np.ndarray, f: Position = pos) -> np.ndarray:
                return f(t_, d_, boom)

            for place in (p3, p2):
                x = place(th, d)
                a = derivative(derivative(x, dt), dt)
                j_th = (place(th + eps, d) - place(th - eps, d)) / (2 * eps)
                j_d = (place(th, d + eps) - place(th, d - eps)) / (2 * eps)
                sign = 1.0 if place is p3 else -1.0
                # Gravity is the same vertical vector in both; it cancels in the difference.
                q[:, 0] += sign * np.einsum("ij,ij->i", mass * a, j_th)
                q[:, 1] += sign * np.einsum("ij,ij->i", mass * a, j_d)
        return q


@register_effect
class SensorTimeSkewEffect(SimEffect):
    """The arm-geometry sensor's readings are late against the current logger.

    The MTi and laser on the saddle block report the arm as it was ``magnitude``
    milliseconds earlier (negative: the logger's analog channels are the late ones).
    Implemented on the fine-grid truth, so the delayed reading is the real past
    position, with the sensor noise already drawn.
    """

    name = "sensor_time_skew"
    default_magnitude = 160.0
    magnitude_unit = "ms (arm sensor late; negative: currents late)"
    description = "one sensor stream delayed against the others"
    typical_range = (140.0, 220.0)
    forms = ("arm", "mti")
    """arm: the MTi and the laser late together; mti: only the MTi (handle and swing)
    is late, the laser's crowd reading is on time (one device's stream, as a buffered
    serial link or a CAN gateway makes it)."""

    def measure(self, cols: dict[str, np.ndarray], ctx: dict[str, Any],
                rng: np.random.Generator) -> None:
        m = ctx["motion"]
        tau = self.magnitude / 1000.0
        t = cols["time_s"]
        if tau >= 0:
            late_ones: list[tuple[str, np.ndarray, Callable[[np.ndarray], np.ndarray]]] = [
                ("handle_deg", m.th, np.degrees), ("crowd_m", m.d, lambda x: x),
                ("swing_deg", m.swing, np.degrees)]
            if self.form == "mti":
                late_ones = [late_ones[0], late_ones[2]]
            for name, truth, conv in late_ones:
                late = np.interp(t - tau, m.t, truth)
                cols[name] = cols[name] + conv(late) - conv(np.interp(t, m.t, truth))
        else:
            for name in ("hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a", "swing_a",
                         "boom_deg", "roll_deg", "pitch_deg"):
                x = cols[name]
                cols[name] = np.interp(t + tau, t, x)


@register_effect
class PayloadCogOffsetEffect(SimEffect):
    """The load in the dipper has its centre of gravity forward of and below the bail.

    The payload body is moved from the bail pin to a point fixed in the dipper: a
    distance ``magnitude`` from the bail, 35 degrees below the handle axis.
    """

    name = "payload_cog_offset"
    default_magnitude = 0.8
    magnitude_unit = "m (bail to load centre)"
    description = "payload centre of gravity away from the bail"
    typical_range = (0.5, 1.5)
    angle_deg = -35.0
    forms = ("point", "heap")
    """point: the load as one mass at its centre; heap: the material where it sits in
    the dipper, a heap over the dipper's floor (point masses on a grid of the bowl,
    heavier towards the back wall), with its own extent and inertia."""

    def _heap(self) -> list[tuple[float, float, float]]:
        """(share, along the handle, across it) of the heap's parts, in the dipper's frame.
        The bowl spans 0.3-1.7 x ``magnitude`` forward of the bail and 0.1-1.1 x below
        it; the fill is deeper at the back (a heap leans on the back wall)."""
        r = self.magnitude
        pts = []
        for u in np.linspace(0.3, 1.7, 6):
            for v in np.linspace(0.1, 1.1, 5):
                w = (1.8 - u) * (1.2 - v)
                pts.append((w, u * r * np.cos(np.radians(self.angle_deg)) + 0.2 * r,
                            -v * r * np.sin(np.radians(-self.angle_deg))))
        total = sum(p[0] for p in pts)
        return [(w / total, a, b) for w, a, b in pts]

    def bodies(self, ctx: dict[str, Any]) -> None:
        from shoveld.sim.plant import Body

        def place(a: float, b: float) -> Any:
            def load_pos(th: np.ndarray, d: np.ndarray, boom: np.ndarray) -> np.ndarray:
                c, s = np.cos(th), np.sin(th)
                return np.stack([(d + a) * c - b * s, (d + a) * s + b * c], axis=-1)
            return load_pos

        if self.form == "point":
            a = self.magnitude * np.cos(np.radians(self.angle_deg))
            b = self.magnitude * np.sin(np.radians(self.angle_deg))
            for body in ctx["bodies"]:
                if body.name == "payload":
                    body.position = place(a, b)
            return
        old = next(bd for bd in ctx["bodies"] if bd.name == "payload")
        ctx["bodies"] = [bd for bd in ctx["bodies"] if bd is not old]
        for k, (w, a, b) in enumerate(self._heap()):
            ctx["bodies"].append(Body(f"payload{k}", np.asarray(old.mass) * w, place(a, b)))


@register_effect
class HoistRopeMassEffect(SimEffect):
    """The hoist rope between sheave and bail has weight (and inertia).

    The rope is discretised into elements along the sheave-bail chord; their mass
    is lam times the current free length. The generalized gravity force is the
    numerical gradient of the rope's potential energy, counting the rope that
    leaves the span over the sheave as wound on the drum (at the drum's height);
    the elements' inertia enters by virtual work.
    """

    name = "hoist_rope_mass"
    default_magnitude = 120.0
    magnitude_unit = "kg/m (both hoist ropes)"
    description = "hoist rope weight between sheave and bail"
    typical_range = (100.0, 160.0)
    n_elements = 6

    def _energy(self, th: np.ndarray, d: np.ndarray, boom: np.ndarray, l_bs: float
                ) -> np.ndarray:
        b, p = _sheave(boom, l_bs), _bail(th, d)
        length = np.linalg.norm(b - p, axis=1)
        s = (np.arange(self.n_elements) + 0.5) / self.n_elements
        heights = b[:, 1][:, None] + s[None, :] * (p[:, 1] - b[:, 1])[:, None]
        span = self.magnitude * 9.81 * (length / self.n_elements) * heights.sum(axis=1)
        wound = -self.magnitude * 9.81 * length * DRUM_XY[1]
        return span + wound

    def extra_forces(self, ctx: dict[str, Any]) -> np.ndarray:
        from shoveld.sim.plant import Body, generalized_forces

        m, pp, dt = ctx["motion"], ctx["params"], ctx["dt"]
        th, d = m.th, m.d
        boom = ctx.get("boom_true", m.boom)
        eps = 1e-6
        q = np.zeros((len(th), 2))
        q[:, 0] = (self._energy(th + eps, d, boom, pp.l_bs)
                   - self._energy(th - eps, d, boom, pp.l_bs)) / (2 * eps)
        q[:, 1] = (self._energy(th, d + eps, boom, pp.l_bs)
                   - self._energy(th, d - eps, boom, pp.l_bs)) / (2 * eps)
        length = np.linalg.norm(_sheave(boom, pp.l_bs) - _bail(th, d), axis=1)
        bodies = []
        for k in range(self.n_elements):
            s = (k + 0.5) / self.n_elements

            def pos(t_: np.ndarray, d_: np.ndarray, bo_: np.ndarray, s: float = s) -> np.ndarray:
                return _sheave(bo_, pp.l_bs) + s * (_bail(t_, d_) - _sheave(bo_, pp.l_bs))
            bodies.append(Body(f"rope{k}", self.magnitude * length / self.n_elements, pos))
        q += generalized_forces(bodies, th, d, boom, dt, np.zeros(2))
        return q


@register_effect
class LoadDependentFrictionEffect(SimEffect):
    """Coulomb friction grows with the normal forces the load puts on the bearings.

    Saddle block: mu times the load's weight component across the handle
    (m g |cos th|). Shipper shaft: mu times the load's weight on a 0.5 m effective
    bearing/pinion radius. Same velocity taper as the plant's own friction.
    """

    name = "load_dependent_friction"
    default_magnitude = 0.08
    magnitude_unit = "(friction coefficient)"
    description = "Coulomb friction growing with the payload"
    typical_range = (0.06, 0.12)
    shaft_radius_m = 0.5

    def friction(self, ctx: dict[str, Any], fric: np.ndarray) -> np.ndarray:
        m, pp = ctx["motion"], ctx["params"]
        s = pp.friction_smoothing
        w = m.payload * 9.81
        out = fric.copy()
        out[:, 0] += self.magnitude * self.shaft_radius_m * w * np.tanh(ctx_rate(ctx, 0) / s)
        out[:, 1] += self.magnitude * w * np.abs(np.cos(m.th)) * np.tanh(ctx_rate(ctx, 1) / s)
        return out


def ctx_rate(ctx: dict[str, Any], j: int) -> np.ndarray:
    from shoveld.sim.plant import derivative

    m = ctx["motion"]
    return derivative(m.th if j == 0 else m.d, ctx["dt"])


@register_effect
class CurrentSaturationEffect(SimEffect):
    """Motor force falls behind the armature current at high current.

    Each DC motor's force is K I_s asinh(i / I_s): armature reaction and iron
    saturation flatten the torque curve without a hard ceiling. I_s is set so the
    force deficit is ``magnitude`` at 250 A per motor. Both hoist motors (sharing the
    rope pull at the plant's split) and the crowd motor; the currents that deliver
    the required forces are found by Newton iteration.
    """

    name = "current_saturation"
    default_magnitude = 0.12
    magnitude_unit = "(force deficit at 250 A per motor)"
    description = "force sub-linear in armature current"
    typical_range = (0.1, 0.15)
    ref_a = 250.0
    forms = ("asinh", "knee")
    """asinh: a smooth curve; knee: linear up to a knee at 100 A per motor, a reduced slope
    above it (the pole tips saturating), rounded over 20 A."""
    knee_a = 100.0

    def _force(self, i: np.ndarray, i_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Force per unit of the linear constant, and its derivative, at current i."""
        if self.form == "asinh":
            return i_s * np.arcsinh(i / i_s), 1.0 / np.sqrt(1.0 + (i / i_s) ** 2)
        k, w = self.knee_a, 20.0
        slope = 1.0 - self.magnitude * self.ref_a / (self.ref_a - k)
        x = np.abs(i) - k
        soft = w * np.logaddexp(0.0, x / w)  # smooth max(0, |i| - knee)
        f = np.sign(i) * (np.abs(i) - (1.0 - slope) * soft)
        df = 1.0 - (1.0 - slope) / (1.0 + np.exp(-x / w))
        return f, df

    def _i_sat(self) -> float:
        from scipy.optimize import brentq

        if self.magnitude <= 0:
            return np.inf
        x = brentq(lambda x: np.arcsinh(x) / x - (1.0 - self.magnitude), 1e-6, 1e3)
        return self.ref_a / x

    def currents(self, ctx: dict[str, Any]) -> None:
        i_s = self._i_sat()
        if not np.isfinite(i_s):
            return
        split = ctx["params"].hoist_split
        for key, shares in (("i_h", (split, 1.0 - split)), ("i_c", (1.0,))):
            lin = ctx[key]  # the current a linear motor would need
            i = lin.copy()
            for _ in range(50):
                parts = [self._force(sh * i, i_s) for sh in shares]
                f = sum(p[0] for p in parts) - lin
                df = sum(sh * p[1] for sh, p in zip(shares, parts, strict=True))
                step = f / df
                i = i - step
                if np.max(np.abs(step)) < 1e-9:
                    break
            ctx[key] = i


@register_effect
class GroundSlopeEffect(SimEffect):
    """The crawlers stand on a slope; the house swings on a tilted axis.

    The ground is tilted by ``magnitude`` degrees towards 40 degrees of swing, so the
    house's pitch and roll change as it swings. The arm's motion is prescribed in the
    arm plane from the direction of gravity's part in that plane (the handle sensor is
    gravity-referenced); that part is g times the cosine of the roll, and the boom,
    fixed to the deck, has its sheave at the deck angle plus the deck's lean in the
    plane (3D trigonometry, not a small-angle formula). The boom column stays
    deck-relative, the handle sensor reads the handle's elevation above the true
    horizontal, and the cab inclinometer reads pitch and roll.
    """

    name = "ground_slope"
    default_magnitude = 5.0
    magnitude_unit = "deg (ground slope)"
    description = "machine on a slope, inclinometer sees it"
    typical_range = (4.0, 7.0)
    forms = ("downhill_40", "downhill_205")
    """The swing angle the ground falls towards (the truck on the low side or the high)."""

    @property
    def downhill_deg(self) -> float:
        return float(self.form.split("_")[1])

    def _tilt(self, swing: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """House pitch and roll (rad), and the deck's tilt in the arm plane seen from the
        plane's own horizontal (the angle to add to the deck-relative boom)."""
        a = np.radians(self.magnitude)
        rel = np.radians(self.downhill_deg) - swing
        pitch = np.arcsin(np.sin(a) * np.cos(rel))
        roll = np.arcsin(np.sin(a) * np.sin(rel))
        # Gravity in the house frame is -g (sin pitch, cos a, -sin roll) on (x_H, y_H, z_H);
        # its part in the arm plane (x_H, y_H) leans from -y_H by atan2(sin pitch, cos a),
        # which is how far the deck (and the boom on it) is raised in that plane.
        in_plane = np.arctan2(np.sin(pitch), np.cos(a))
        return pitch, roll, in_plane

    def before_dynamics(self, ctx: dict[str, Any]) -> None:
        m = ctx["motion"]
        _, roll, in_plane = self._tilt(m.swing)
        ctx["boom_true"] = ctx.get("boom_true", m.boom) + in_plane
        g = 9.81 * np.cos(roll)
        ctx["gravity"] = np.stack([np.zeros_like(g), -g], axis=-1)

    def measure(self, cols: dict[str, np.ndarray], ctx: dict[str, Any],
                rng: np.random.Generator) -> None:
        m = ctx["motion"]
        idx = ctx["sample_index"]
        pitch, roll, _ = self._tilt(m.swing[idx])
        th = m.th[idx]
        # The plane of the arm leans sideways by the roll: the handle's true elevation.
        elev = np.arcsin(np.cos(roll) * np.sin(th))
        cols["handle_deg"] = cols["handle_deg"] + np.degrees(elev - th)
        cols["pitch_deg"] = cols["pitch_deg"] + np.degrees(pitch)
        cols["roll_deg"] = cols["roll_deg"] + np.degrees(roll)


class _FixedBoom(SimEffect):
    """Internal: holds the boom at a given angle (used while iterating the boom's sag)."""

    name = "_fixed_boom"

    def __init__(self, boom: np.ndarray) -> None:
        super().__init__(0.0)
        self.boom = boom

    def before_dynamics(self, ctx: dict[str, Any]) -> None:
        ctx["boom_true"] = self.boom


@register_effect
class BoomSuspensionSpringEffect(SimEffect):
    """The boom rotates about its foot as the suspension ropes stretch under load.

    The hoist rope pulls the boom-point sheave towards the bail and towards the drum;
    the moment of those two pulls about the boom foot, over the suspension's
    rotational stiffness, lowers the boom. The rope pull itself depends on the
    boom angle, so the plant is re-run to a fixed point. The boom column still shows
    the boom at rest (the inclinometer is filtered over minutes, as boom vibration
    demands), so the model does not see the sag. Magnitude: the drop at 1 MN of rope
    pull with the dipper at th = 0, d = 8.5 m.
    """

    name = "boom_suspension_spring"
    default_magnitude = 2.0
    magnitude_unit = "deg (boom drop at 1 MN rope pull)"
    description = "boom angle moving with the rope load"
    typical_range = (1.5, 3.0)
    iterations = 3

    @staticmethod
    def _moment(th: np.ndarray, d: np.ndarray, boom: np.ndarray, tension: np.ndarray,
                l_bs: float) -> np.ndarray:
        b = _sheave(boom, l_bs)
        foot = -BOOM_FOOT_BELOW_SHAFT_M * np.stack([np.cos(boom), np.sin(boom)], axis=-1)
        to_bail = _bail(th, d) - b
        to_drum = DRUM_XY[None, :] - b
        f = tension[:, None] * (to_bail / np.linalg.norm(to_bail, axis=1, keepdims=True)
                                + to_drum / np.linalg.norm(to_drum, axis=1, keepdims=True))
        arm = b - foot
        return arm[:, 0] * f[:, 1] - arm[:, 1] * f[:, 0]

    def drop_deg_at(self, pull_n: float) -> float:
        """The boom's drop (deg) at a rope pull of ``pull_n`` with the dipper where the
        magnitude is stated (th = 0, d = 8.5 m): the truth a model's drop at that pose is
        held against (the bench's coverage, the tests)."""
        return self.magnitude * pull_n / 1e6

    def before_dynamics(self, ctx: dict[str, Any]) -> None:
        from shoveld.sim.plant import Plant

        m, pp = ctx["motion"], ctx["params"]
        one = np.ones(1)
        ref = self._moment(0.0 * one, 8.5 * one, np.radians(pp.boom_deg) * one, 1e6 * one,
                           pp.l_bs)[0]
        compliance = np.radians(self.magnitude) / abs(ref)
        others = [e for e in ctx.get("effects", []) if e is not self]
        boom = m.boom
        for _ in range(self.iterations):
            sub = Plant(pp, [*others, _FixedBoom(boom)]).run(m)
            boom = m.boom + compliance * self._moment(m.th, m.d, boom, sub["rope_force"],
                                                      pp.l_bs)
        ctx["boom_true"] = boom
