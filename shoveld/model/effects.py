"""Extension terms of the shovel model: the physics the thesis's two-joint model omits.

Each term is the model-side, analytic description of one physical cause, written
from the equations of motion in the notation of ``shoveld.model.terms`` (residual
``e = W p + m (phi + Psi p)``, handle torque and crowd force). Wherever possible a
term is linear in its new parameters, so it is identified by the same least
squares as the base model; a nonlinear constant (a delay, a radius) is a
hyper-parameter found by a 1-D search (``search`` gives its bounds) and recorded
in the params file's ``[hyper]`` section.

The simulator's versions of these effects (``shoveld.sim.effects``) are written
independently, in Cartesian/virtual-work or drive/sensor form; this module never
imports them.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from shoveld.model.geometry import L_BS, G
from shoveld.model.kin import Kinematics
from shoveld.model.terms import SIGN_EPS_D, SIGN_EPS_TH, Term, _stack, register_term, smooth_sign


def _unit_hoist(k: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    """Generalized force on (th, d) of a unit rope tension, sign of the residual: dl/dq."""
    return -k.d * k.sin_a3, k.cos_a3


def _unit_hoist_dboom(k: Kinematics) -> tuple[np.ndarray, np.ndarray]:
    """Derivative of ``_unit_hoist`` with respect to the boom angle (per radian).

    Differentiating the rope geometry of ``rope_geometry``: the sheave moves on a
    circle of radius L_BS about the shipper shaft, so the rope's length and both
    angle functions of a3 change with the boom angle.
    """
    b, th = k.boom, k.th
    rx = L_BS * np.cos(b) - k.d * np.cos(th)
    ry = L_BS * np.sin(b) - k.d * np.sin(th)
    dl = L_BS * (ry * np.cos(b) - rx * np.sin(b)) / k.l_sd
    dsin = (L_BS * np.cos(b - th) - k.sin_a3 * dl) / k.l_sd
    dcos = (L_BS * np.sin(b - th) - k.cos_a3 * dl) / k.l_sd
    return -k.d * dsin, dcos


class ExtensionTerm(Term):
    """Base of the extension terms: what the diagnosis needs beyond the ``Term`` API."""

    static_params: ClassVar[tuple[str, ...]] = ()
    """Own parameters identified in the static (gravity) stage with Md, MdLc, K_H, K_C
    (the staged calibrator reads this attribute); the rest go to the dynamic stage."""
    search: ClassVar[dict[str, tuple[float, float]]] = {}
    """Hyper-parameters found by a 1-D search on training data, with their bounds."""
    defaults: ClassVar[dict[str, float]] = {}
    cause: ClassVar[str] = ""
    """The physical cause in the words of a field engineer (the report's headline)."""
    signature: ClassVar[str] = ""
    """The variable the residual should be plotted against to see this cause."""

    def __init__(self, **hyper: Any) -> None:
        super().__init__(**{**self.defaults, **hyper})

    def h(self, name: str) -> float:
        return float(self.hyper[name])

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        """Physical quantities implied by the identified parameters (for the report)."""
        return {}


@register_term
class HoistFieldWeakening(ExtensionTerm):
    """K_H follows the hoist field current through the magnetisation curve.

    A DC motor's torque per ampere is proportional to its flux, and the flux to the
    field current only up to the knee of the magnetisation curve. Around the nominal
    hoisting field i0 the curve is a smooth function, written as a cubic in
    x = i_f / i0 - 1: K_H(i_f) = K_H + K_H1 x + K_H2 x^2 + K_H3 x^3. Each coefficient
    multiplies the rope-tension column, so the term is linear; with it the weak-field
    samples (lowering at ~30 A) become usable.
    """

    name = "hoist_field_weakening"
    params = ("K_Hf1", "K_Hf2", "K_Hf3")
    units = ("N/A", "N/A", "N/A")
    description = "hoist force per ampere changing with the hoist field current"
    cause = ("the hoist motors' pull per ampere drops when the hoist field current drops "
             "(field weakening, magnetic saturation of the field)")
    signature = "hoist_field_a"
    uses_field_current = True
    defaults = {"field_nominal_a": 70.0}

    def columns(self, k: Kinematics) -> np.ndarray:
        x = k.i_hf / self.h("field_nominal_a") - 1.0
        u_th, u_d = _unit_hoist(k)
        i = k.i_h_est
        return _stack(*[(i * x**n * u_th, i * x**n * u_d) for n in (1, 2, 3)])

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        i0 = self.h("field_nominal_a")
        out = {}
        for i_f in (30.0, 50.0, 65.0):
            x = i_f / i0 - 1.0
            ratio = 1.0 + sum(values[f"K_Hf{n}"] * x**n for n in (1, 2, 3)) / values["K_H"]
            out[f"K_H ratio at {i_f:g} A field"] = ratio
        return out


@register_term
class SwingCentrifugal(ExtensionTerm):
    """Centrifugal forces of the swing on both joints.

    The arm plane turns about the swing axis at rate w. A point mass at distance rho
    along the handle lies at R = R0 + rho cos th from the swing axis (R0: axis to
    shipper shaft) and feels w^2 R outward, horizontal. Its virtual work on (th, d)
    adds w^2 R rho sin th to the handle torque and -w^2 R cos th to the crowd force.
    Summed over the arm (a slender body: mass Md at r = d - Lc, inertia J - Md Lc^2
    about its centre) this is new physics on the *existing* parameters Md, MdLc and J,
    and per kilogram of payload a known term; dJ_sw is the arm's departure from a
    slender body (its width), and R0 is found by a 1-D search.
    """

    name = "swing_centrifugal"
    params = ("dJ_sw",)
    units = ("kg m^2",)
    description = "centrifugal forces while swinging"
    cause = ("swinging throws the dipper outward: the centrifugal pull of the turning "
             "arm and load loads the hoist and crowd")
    signature = "swing_rate"
    defaults = {"R0_m": 4.5}
    search = {"R0_m": (0.0, 9.0)}

    def _w2(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return k.swing_rate**2, np.cos(k.th), np.sin(k.th)

    def columns(self, k: Kinematics) -> np.ndarray:
        w2, c, s = self._w2(k)
        return _stack((w2 * c * s, np.zeros_like(c)))

    def shared_columns(self, k: Kinematics) -> dict[str, np.ndarray]:
        w2, c, s = self._w2(k)
        r0, d = self.h("R0_m"), k.d
        md = np.stack([w2 * (r0 * d * s + d * d * c * s), -w2 * (r0 * c + d * c * c)], axis=-1)
        mlc = np.stack([-w2 * (r0 * s + 2.0 * d * c * s), w2 * c * c], axis=-1)
        j = np.stack([w2 * c * s, np.zeros_like(c)], axis=-1)
        return {"Md": md, "MdLc": mlc, "J": j}

    def payload_phi(self, k: Kinematics) -> np.ndarray:
        w2, c, s = self._w2(k)
        r0, d = self.h("R0_m"), k.d
        return np.stack([w2 * (r0 * d * s + d * d * c * s), -w2 * (r0 * c + d * c * c)], axis=-1)


ARM_STREAM = ("handle_deg", "crowd_m", "swing_deg")
"""Signals of the saddle-block arm-geometry sensor (MTi and laser)."""
DRIVE_STREAM = ("hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a", "crowd_field_a", "swing_a",
                "swing_field_a", "boom_deg", "roll_deg", "pitch_deg")
"""Signals of the analog logger (Hall-effect current sensors and inclinometers)."""


def _delay_columns(t: np.ndarray, cols: dict[str, np.ndarray], names: tuple[str, ...],
                   delay: float) -> None:
    """x(t) <- x(t - delay) by linear interpolation; NaN before the first sample."""
    for n in names:
        x = cols[n]
        ok = np.isfinite(x)
        if ok.sum() < 2:
            continue
        y = np.interp(t - delay, t[ok], x[ok], left=np.nan, right=np.nan)
        cols[n] = y


class StreamDelay:
    """Causal delay line for some fields of a ``Sample`` (live twin of the transform)."""

    def __init__(self, names: tuple[str, ...], delay_s: float) -> None:
        self.names = names
        self.delay = delay_s
        self.buf: deque[tuple[float, tuple[float, ...]]] = deque()

    def __call__(self, s: Any) -> Any:
        t = s.time_s
        self.buf.append((t, tuple(getattr(s, n) for n in self.names)))
        target = t - self.delay
        while len(self.buf) >= 2 and self.buf[1][0] <= target:
            self.buf.popleft()
        t0, v0 = self.buf[0]
        if target < t0:
            vals = tuple(math.nan for _ in self.names)
        elif len(self.buf) >= 2:
            t1, v1 = self.buf[1]
            a = (target - t0) / (t1 - t0) if t1 > t0 else 0.0
            vals = tuple(x0 + a * (x1 - x0) for x0, x1 in zip(v0, v1, strict=True))
        else:
            vals = v0
        return replace(s, **dict(zip(self.names, vals, strict=True)))


@register_term
class SensorTimeSkew(ExtensionTerm):
    """One sensor stream is late against the other.

    The arm-geometry sensor on the saddle block and the analog logger of currents
    and inclinometers sample at different moments and with different filters. With
    ``delay_s`` > 0 the arm readings are that much older than the currents; the
    transform re-aligns the streams by delaying the leading one (causal, so the live
    engine does the same with a delay line). The delay is found by a 1-D search.
    """

    name = "sensor_time_skew"
    params = ()
    units = ()
    description = "arm sensor and current logger out of step"
    cause = ("the arm-position sensor and the current logger are out of step in time "
             "(a sensor stream is delayed)")
    signature = "time_shift"
    defaults = {"delay_s": 0.0}
    search = {"delay_s": (-0.3, 0.3)}

    def columns(self, k: Kinematics) -> np.ndarray:
        return np.zeros((len(k), 2, 0))

    def _late(self) -> tuple[tuple[str, ...], float]:
        d = self.h("delay_s")
        return (DRIVE_STREAM, d) if d >= 0 else (ARM_STREAM, -d)

    def transform(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        names, delay = self._late()
        if delay == 0.0:
            return cols
        out = dict(cols)
        _delay_columns(np.asarray(cols["time_s"]), out, names, delay)
        return out

    def stream(self) -> Callable[[Any], Any] | None:
        """The live version of ``transform``: a causal delay line on samples."""
        names, delay = self._late()
        return StreamDelay(names, delay) if delay > 0 else None


@register_term
class PayloadCogOffset(ExtensionTerm):
    """The payload's centre of gravity is not at the bail.

    The load sits in the dipper forward of and below the bail pin: at p = (d + a) u
    + b n (u along the handle, n perpendicular, up). Virtual work of a point mass
    there, expanded to first order in a and b, gives per kilogram of payload
    a [2 d th'' + 2 d' th' + g cos th, -th'^2] + b [-d'' - g sin th, -th''];
    the (a^2 + b^2) th'' part is second order and left out.
    """

    name = "payload_cog_offset"
    params = ("cog_fwd", "cog_up")
    units = ("m", "m")
    description = "load centre of gravity away from the bail"
    cause = ("the load's centre of gravity sits forward of / below the bail pin, so it "
             "hangs on a longer lever than the model assumes")
    signature = "handle_angle"
    static_params = ("cog_fwd", "cog_up")

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((z, z), (z, z))

    def payload_columns(self, k: Kinematics) -> np.ndarray:
        c, s = np.cos(k.th), np.sin(k.th)
        fwd = (2.0 * k.d * k.thdd + 2.0 * k.dd * k.thd + G * c, -k.thd * k.thd)
        up = (-k.ddd - G * s, -k.thdd)
        return _stack(fwd, up)


@register_term
class HoistRopeMass(ExtensionTerm):
    """The weight of the hoist rope between the boom-point sheave and the bail.

    Potential energy of a taut rope of mass lam per metre, straight from the sheave B
    to the bail P, with the rope wound in at the drum at height y_D:
    V = lam g l ((y_B + y_P) / 2 - y_D). Its gradient is the generalized force:
    lam g [dl/dq (y_B + y_P) / 2 + l / 2 dy_P/dq] - (lam g y_D) dl/dq. Linear in lam and
    in T0 = lam g y_D (a constant rope-tension offset from the drum-side rope).
    """

    name = "hoist_rope_mass"
    params = ("rope_kg_m", "rope_T0")
    units = ("kg/m", "N")
    description = "weight of the hoist rope"
    cause = ("the hoist rope's own weight between the boom-point sheave and the bail "
             "is carried by the hoist")
    signature = "rope_length"
    static_params = ("rope_kg_m", "rope_T0")

    def columns(self, k: Kinematics) -> np.ndarray:
        u_th, u_d = _unit_hoist(k)
        s = np.sin(k.th)
        ymid = 0.5 * (L_BS * np.sin(k.boom) + k.d * s)
        lam = (G * (u_th * ymid + 0.5 * k.l_sd * k.d * np.cos(k.th)),
               G * (u_d * ymid + 0.5 * k.l_sd * s))
        return _stack(lam, (-u_th, -u_d))


@register_term
class LoadDependentFriction(ExtensionTerm):
    """Coulomb friction that grows with the load.

    The normal forces in the shipper-shaft bearings and between the handle and the
    saddle block grow with the weight carried, and Coulomb friction with them:
    fc3 + m fc3_kg and fc4 + m fc4_kg, each times the (smoothed) sign of the rate.
    Linear, in the payload columns.
    """

    name = "load_dependent_friction"
    params = ("fc3_kg", "fc4_kg")
    units = ("N m/kg", "N/kg")
    description = "friction growing with the load"
    cause = ("friction in the shipper shaft and the saddle block grows with the load "
             "in the dipper")
    signature = "payload_x_direction"

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((z, z), (z, z))

    def payload_columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((smooth_sign(k.thd, SIGN_EPS_TH), z), (z, smooth_sign(k.dd, SIGN_EPS_D)))


@register_term
class CurrentSaturation(ExtensionTerm):
    """Hoist force is not linear in armature current at high current.

    Armature reaction and saturation of the magnetic circuit reduce the flux as the
    armature current grows. To third order (the force is odd in the current):
    F_H = K_H i_H - K_H3 i_H^3 / I_ref^2, with a reference current I_ref (a scale
    only). The cubic uses the current estimated from the neighbouring samples
    (``Kinematics.i_h_est``), so its noise does not correlate with the measured
    current in the hoist column. The crowd motor runs at a fraction of the hoist
    current and is left linear: its cubic would be indistinguishable from K_C.
    """

    name = "current_saturation"
    params = ("K_H3",)
    units = ("N/A",)
    description = "hoist force falling behind the current at high current"
    cause = ("at high current the hoist motors give less pull per ampere "
             "(armature reaction, magnetic saturation)")
    signature = "hoist_current"
    defaults = {"ref_a": 500.0}
    static_params = ("K_H3",)

    def columns(self, k: Kinematics) -> np.ndarray:
        u_th, u_d = _unit_hoist(k)
        ih3 = k.i_h_est**3 / self.h("ref_a") ** 2
        return _stack((-ih3 * u_th, -ih3 * u_d))

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"hoist force deficit at the reference current":
                values["K_H3"] / values["K_H"]}


@register_term
class GroundSlope(ExtensionTerm):
    """The machine stands on a slope; the cab inclinometer sees the tilt.

    The handle angle comes from a gravity-referenced sensor, but the boom angle is
    measured against the machinery deck, so in the gravity frame the boom-point
    sheave sits at boom + pitch: to first order the rope columns change by
    K_H kappa pitch d(rope)/d(boom), with kappa = 1 for a true slope (identified,
    as ``K_H_pitch`` = K_H kappa). Gravity in the arm plane is g cos(roll): a known
    change of the mass columns and of the payload's.
    """

    name = "ground_slope"
    params = ("K_H_pitch",)
    units = ("N/A",)
    description = "machine standing on a slope"
    cause = ("the machine stands on a slope: as it swings, the tilt changes the direction "
             "of gravity against the boom and the arm")
    signature = "pitch"
    static_params = ("K_H_pitch",)

    def columns(self, k: Kinematics) -> np.ndarray:
        g_th, g_d = _unit_hoist_dboom(k)
        q = k.i_h_est * k.pitch
        return _stack((q * g_th, q * g_d))

    def _gravity(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.cos(k.roll) - 1.0, np.cos(k.th), np.sin(k.th)

    def shared_columns(self, k: Kinematics) -> dict[str, np.ndarray]:
        f, c, s = self._gravity(k)
        md = np.stack([f * k.d * G * c, f * G * s], axis=-1)
        mlc = np.stack([-f * G * c, np.zeros_like(c)], axis=-1)
        return {"Md": md, "MdLc": mlc}

    def payload_phi(self, k: Kinematics) -> np.ndarray:
        f, c, s = self._gravity(k)
        return np.stack([f * k.d * G * c, f * G * s], axis=-1)

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"kappa (1 for a true slope)": values["K_H_pitch"] / values["K_H"]}


@register_term
class BoomSuspensionSpring(ExtensionTerm):
    """The boom angle moves with the rope load (suspension ropes and boom stretch).

    The boom point drops in proportion to the rope pull, K_H i_H: boom_true =
    boom - sag i_H / I_ref. To first order the rope columns change by
    -K_H sag (i_H^2 / I_ref) d(rope)/d(boom); the parameter is K_H_sag = K_H sag,
    and sag (rad at the reference current I_ref) follows.
    """

    name = "boom_suspension_spring"
    params = ("K_H_sag",)
    units = ("N/A",)
    description = "boom point dropping under rope load"
    cause = ("the boom suspension ropes stretch under the hoist pull, so the boom point "
             "(and the rope angle) moves with the load")
    signature = "hoist_current"
    defaults = {"ref_a": 500.0}
    static_params = ("K_H_sag",)

    def columns(self, k: Kinematics) -> np.ndarray:
        g_th, g_d = _unit_hoist_dboom(k)
        q = -k.i_h_est**2 / self.h("ref_a")
        return _stack((q * g_th, q * g_d))

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"boom drop at the reference current, deg":
                math.degrees(values["K_H_sag"] / values["K_H"])}


EFFECT_TERMS: tuple[str, ...] = (
    "hoist_field_weakening", "swing_centrifugal", "sensor_time_skew", "payload_cog_offset",
    "hoist_rope_mass", "load_dependent_friction", "current_saturation", "ground_slope",
    "boom_suspension_spring")
"""The candidate library of the diagnosis, in a fixed order."""
