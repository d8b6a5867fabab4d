"""The simulated shovel: prescribed joint motion -> the motor currents it takes.

This is deliberately *not* the model's closed-form equations. Bodies are placed
in Cartesian space by a position function, their accelerations come from
differentiating positions on a fine time grid, and generalized forces from
virtual work with numerical Jacobians. Agreement between this plant and the
model's regressor is therefore a check of the model's derivation, and any
physics added here (an effect) is written independently of the model term that
later tries to explain it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

GRAVITY = np.array([0.0, -9.81])
"""World-frame gravity in the swing plane (x outward, y up), m/s^2."""


@dataclass
class PlantParams:
    """True parameters of the simulated machine (defaults: thesis Table 5 and plausible
    values for what the thesis did not identify)."""

    Md: float = 56960.0
    Lc: float = 3.27
    Izz: float = 6.0e5
    K_H: float = 1715.0
    """Rope force per ampere of total hoist armature current at the nominal field."""
    K_C: float = 4418.0
    fv3: float = 1.5e5
    fc3: float = 4.0e4
    fv4: float = 2.0e4
    fc4: float = 1.5e4
    l_bs: float = 9.21
    boom_deg: float = 45.0
    hoist_field_hoisting_a: float = 70.0
    hoist_field_lowering_a: float = 30.0
    hoist_field_tau_s: float = 0.25
    field_flux_knee_a: float = 45.0
    """Magnetisation curve of the hoist field: flux ~ tanh(i_f / knee)."""
    crowd_field_a: float = 29.0
    swing_field_a: float = 30.0
    K_S: float = 6000.0
    """Swing torque per ampere, N m/A."""
    swing_house_inertia: float = 2.0e7
    swing_radius_m: float = 4.5
    swing_friction: float = 3.0e5
    hoist_split: float = 0.51
    """Share of the rope force carried by hoist motor 1."""
    friction_smoothing: float = 0.002
    """Velocity below which Coulomb friction tapers off (real friction, not the model's)."""

    def flux_ratio(self, i_f: np.ndarray) -> np.ndarray:
        """K_H at field i_f relative to K_H at the hoisting field."""
        k = self.field_flux_knee_a
        return np.tanh(i_f / k) / np.tanh(self.hoist_field_hoisting_a / k)

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.__dict__.items()}


@dataclass
class Motion:
    """Prescribed motion on the fine grid, SI units (angles in rad)."""

    t: np.ndarray
    th: np.ndarray
    d: np.ndarray
    swing: np.ndarray
    boom: np.ndarray
    payload: np.ndarray
    """Mass in the dipper, kg."""
    bank_force: np.ndarray | None = None
    """(N, 2) resisting generalized force of the bank while digging (N m, N); None:
    zeros (``__post_init__`` sets them)."""
    phase: np.ndarray | None = None
    """Truth label per fine sample (index into ``PHASES``); None: zeros, as above."""

    def __post_init__(self) -> None:
        n = len(self.t)
        if self.bank_force is None:
            self.bank_force = np.zeros((n, 2))
        if self.phase is None:
            self.phase = np.zeros(n, dtype=np.int8)


Position = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(th, d, boom) -> (N, 2) position in the swing plane."""


@dataclass
class Body:
    """A mass in the arm: position (and orientation) as a function of the joints."""

    name: str
    mass: np.ndarray | float
    position: Position
    """(th, d, boom) -> (N, 2) position in the swing plane."""
    inertia: float = 0.0
    """Rotational inertia about its centre, perpendicular to the swing plane."""


class PlantContext(dict[str, Any]):
    """Everything a plant stage or an effect needs, by name."""


def derivative(y: np.ndarray, dt: float) -> np.ndarray:
    return np.gradient(y, dt, axis=0, edge_order=2)


def generalized_forces(bodies: list[Body], th: np.ndarray, d: np.ndarray, boom: np.ndarray,
                       dt: float, gravity: np.ndarray = GRAVITY) -> np.ndarray:
    """(N, 2): generalized forces on (th, d) needed to produce the motion of the bodies.

    Virtual work: Q_j = sum_b m_b (a_b - g) . dp_b/dq_j + I_b alpha_b dphi_b/dq_j.
    Accelerations by differentiating positions; Jacobians by central differences.
    """
    eps_th, eps_d = 1e-6, 1e-6
    q = np.zeros((len(th), 2))
    g = np.broadcast_to(gravity, (len(th), 2)) if gravity.ndim == 1 else gravity
    for b in bodies:
        p = b.position(th, d, boom)
        a = derivative(derivative(p, dt), dt)
        j_th = (b.position(th + eps_th, d, boom) - b.position(th - eps_th, d, boom)) / (2 * eps_th)
        j_d = (b.position(th, d + eps_d, boom) - b.position(th, d - eps_d, boom)) / (2 * eps_d)
        m = np.asarray(b.mass, dtype=float)
        m = m[:, None] if m.ndim else m
        f = m * (a - g)
        q[:, 0] += np.einsum("ij,ij->i", f, j_th)
        q[:, 1] += np.einsum("ij,ij->i", f, j_d)
        if b.inertia:
            # Bodies in the arm turn with the handle: orientation = th.
            alpha = derivative(derivative(th, dt), dt)
            q[:, 0] += b.inertia * alpha
    return q


def rope_force_geometry(th: np.ndarray, d: np.ndarray, boom: np.ndarray, l_bs: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Generalized force on (th, d) of a unit rope tension pulling the bail to the sheave.

    Computed as the virtual work of the force vector: tau = P x f, F_u = f . u.
    """
    u = np.stack([np.cos(th), np.sin(th)], axis=-1)
    p = d[:, None] * u
    sheave = l_bs * np.stack([np.cos(boom), np.sin(boom)], axis=-1)
    r = sheave - p
    f = r / np.linalg.norm(r, axis=1, keepdims=True)
    torque = p[:, 0] * f[:, 1] - p[:, 1] * f[:, 0]
    along = np.einsum("ij,ij->i", f, u)
    return torque, along


def rope_length(th: np.ndarray, d: np.ndarray, boom: np.ndarray, l_bs: float) -> np.ndarray:
    u = np.stack([np.cos(th), np.sin(th)], axis=-1)
    sheave = l_bs * np.stack([np.cos(boom), np.sin(boom)], axis=-1)
    return np.linalg.norm(sheave - d[:, None] * u, axis=1)


def arm_bodies(pp: PlantParams, payload: np.ndarray) -> list[Body]:
    """The dipper-and-handle body and the payload as a point mass at the bail."""

    def arm_pos(th: np.ndarray, d: np.ndarray, boom: np.ndarray) -> np.ndarray:
        r = d - pp.Lc
        return np.stack([r * np.cos(th), r * np.sin(th)], axis=-1)

    def bail_pos(th: np.ndarray, d: np.ndarray, boom: np.ndarray) -> np.ndarray:
        return np.stack([d * np.cos(th), d * np.sin(th)], axis=-1)

    return [Body("arm", pp.Md, arm_pos, pp.Izz), Body("payload", payload, bail_pos)]


def first_order_lag(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """Causal first-order lag (field winding inductance)."""
    from scipy.signal import lfilter

    a = dt / (tau + dt)
    y, _ = lfilter([a], [1, a - 1], x, zi=[x[0] * (1 - a)])
    return y


class Plant:
    """Inverse dynamics of the shovel arm, with optional effects (``shoveld.sim.effects``)."""

    def __init__(self, params: PlantParams | None = None, effects: list[Any] | None = None,
                 drive: Any = None) -> None:
        self.p = params or PlantParams()
        self.effects = list(effects or [])
        self.drive = drive
        """A ``shoveld.sim.machine.FieldDrive`` (field weakening above base speed), or None
        for the two-level field of the thesis."""

    def run(self, motion: Motion) -> PlantContext:
        """Currents and field currents (true, noise-free) for the prescribed motion."""
        pp = self.p
        dt = float(motion.t[1] - motion.t[0])
        ctx = PlantContext(motion=motion, params=pp, dt=dt, effects=self.effects,
                           drive=self.drive)
        for e in self.effects:
            e.before_dynamics(ctx)
        th, d, boom = motion.th, motion.d, ctx.get("boom_true", motion.boom)
        ctx["bodies"] = arm_bodies(pp, motion.payload)
        for e in self.effects:
            e.bodies(ctx)
        q = generalized_forces(ctx["bodies"], th, d, boom, dt, ctx.get("gravity", GRAVITY))
        for e in self.effects:
            q = q + e.extra_forces(ctx)
        thd, dd = derivative(th, dt), derivative(d, dt)
        s = pp.friction_smoothing
        fric = np.stack([pp.fv3 * thd + pp.fc3 * np.tanh(thd / s),
                         pp.fv4 * dd + pp.fc4 * np.tanh(dd / s)], axis=-1)
        for e in self.effects:
            fric = e.friction(ctx, fric)
        assert motion.bank_force is not None  # Motion.__post_init__ sets it
        need = q + fric + motion.bank_force
        tau_u, along_u = rope_force_geometry(th, d, boom, pp.l_bs)
        rope = need[:, 0] / tau_u
        crowd_force = need[:, 1] - rope * along_u
        lr = derivative(rope_length(th, d, boom, pp.l_bs), dt)
        if self.drive is None:
            # Hoist field follows the rope's direction: hoisting (rope shortening) 70 A,
            # lowering 30 A, through the winding's first-order lag.
            target = np.where(lr > 0.02, pp.hoist_field_lowering_a, pp.hoist_field_hoisting_a)
            i_hf = first_order_lag(target, dt, pp.hoist_field_tau_s)
            flux = pp.flux_ratio
        else:
            i_hf = first_order_lag(self.drive.field_target(lr), dt, self.drive.tau_s)
            flux = self.drive.flux_ratio
        ctx.update(need=need, rope_force=rope, crowd_force=crowd_force, i_hf=i_hf, thd=thd,
                   dd=dd)
        for e in self.effects:
            e.before_currents(ctx)
        k_h = pp.K_H * flux(ctx["i_hf"])
        i_h = ctx["rope_force"] / k_h
        i_c = ctx["crowd_force"] / pp.K_C
        ctx.update(i_h=i_h, i_c=i_c)
        # Currents per kilogram of payload (the Cramer-Rao bound's sensitivities): the
        # payload body alone, through the same virtual work and rope geometry.
        pay = [b for b in ctx["bodies"] if b.name == "payload"]
        if pay:
            unit = replace(pay[0], mass=1.0)
            qm = generalized_forces([unit], th, d, boom, dt, ctx.get("gravity", GRAVITY))
            rope_m = qm[:, 0] / tau_u
            ctx.update(di_h_dm=rope_m / k_h, di_c_dm=(qm[:, 1] - rope_m * along_u) / pp.K_C)
        for e in self.effects:
            e.currents(ctx)
        # Swing: house inertia plus the arm and payload at their radius.
        sw_rate = derivative(motion.swing, dt)
        sw_acc = derivative(sw_rate, dt)
        rad_arm = pp.swing_radius_m + (d - pp.Lc) * np.cos(th)
        rad_pay = pp.swing_radius_m + d * np.cos(th)
        inertia = pp.swing_house_inertia + pp.Md * rad_arm**2 + motion.payload * rad_pay**2
        torque = inertia * sw_acc + pp.swing_friction * np.tanh(sw_rate / 0.01)
        ctx.update(i_s=torque / pp.K_S, swing_rate=sw_rate)
        return ctx
