"""Named physical terms of the shovel model, behind a registry.

The model's two equations of motion (handle rotation th, crowd d) are written as
residuals that vanish for the true parameters p and payload m:

    e(q, q', q'', i) = W(...) p + m * (phi(...) + Psi(...) p) = 0

Each term owns some parameters and contributes their columns of ``W`` (and of
``Psi`` when its effect scales with the payload). A new physical effect is a new
``Term`` subclass registered by name; the params file records the term names so
``calibrate``, ``estimate`` and the daemon rebuild the same model.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from shoveld.model.geometry import G
from shoveld.model.kin import Kinematics

TERMS: dict[str, type[Term]] = {}

SIGN_EPS_TH = 0.004
"""rad/s: velocity at which the smoothed Coulomb sign reaches tanh(1); keeps noise
around standstill from switching friction between +-fc."""
SIGN_EPS_D = 0.006
"""m/s, likewise for the crowd."""


def register_term(cls: type[Term]) -> type[Term]:
    """Class decorator: make a term available by its ``name``."""
    if cls.name in TERMS:
        raise ValueError(f"term {cls.name!r} registered twice")
    TERMS[cls.name] = cls
    return cls


def smooth_sign(v: np.ndarray, eps: float) -> np.ndarray:
    return np.tanh(v / eps)


class Term:
    """One physical contribution to the equations of motion."""

    name: ClassVar[str]
    params: ClassVar[tuple[str, ...]]
    units: ClassVar[tuple[str, ...]]
    description: ClassVar[str] = ""
    """What the term means, in words a field engineer uses."""
    base: ClassVar[bool] = False
    """True for the terms of the thesis's simplified model."""

    def __init__(self, **hyper: Any) -> None:
        self.hyper: dict[str, Any] = dict(hyper)

    def columns(self, k: Kinematics) -> np.ndarray:
        """(N, 2, P): residual of [th, d] equations per unit of each parameter."""
        raise NotImplementedError

    def payload_columns(self, k: Kinematics) -> np.ndarray | None:
        """(N, 2, P) multiplied by the payload mass, or None when the term does not
        depend on the payload."""
        return None

    def transform(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Adjust the raw signals before kinematics (e.g. re-align a delayed stream).

        Receives and returns the signals-table columns; the default is identity.
        """
        return cols

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.hyper})" if self.hyper else type(self).__name__


def _stack(*eqs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Columns given as (th_eq, d_eq) pairs -> (N, 2, P)."""
    out = np.empty((len(eqs[0][0]), 2, len(eqs)))
    for j, (th_eq, d_eq) in enumerate(eqs):
        out[:, 0, j] = th_eq
        out[:, 1, j] = d_eq
    return out


def payload_phi(k: Kinematics) -> np.ndarray:
    """(N, 2): the payload as a point mass at the bail, per kilogram."""
    th_eq = k.d * k.d * k.thdd + 2.0 * k.d * k.dd * k.thd + k.d * G * np.cos(k.th)
    d_eq = k.ddd - k.d * k.thd * k.thd + G * np.sin(k.th)
    return np.stack([th_eq, d_eq], axis=-1)


@register_term
class RigidArm(Term):
    """Dipper and handle as one rigid body with its centre of gravity on the handle
    axis at r = d - Lc: gravity, Coriolis and the parallel-axis part of inertia."""

    name = "rigid_arm"
    params = ("Md", "MdLc")
    units = ("kg", "kg m")
    description = "weight and inertia of the dipper and handle"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        cth, sth = np.cos(k.th), np.sin(k.th)
        md_th = k.d * k.d * k.thdd + 2.0 * k.d * k.dd * k.thd + k.d * G * cth
        md_d = k.ddd - k.d * k.thd * k.thd + G * sth
        mlc_th = -2.0 * k.d * k.thdd - 2.0 * k.dd * k.thd - G * cth
        mlc_d = k.thd * k.thd
        return _stack((md_th, md_d), (mlc_th, mlc_d))


@register_term
class HoistDrive(Term):
    """Hoist rope tension K_H * i_H acting at the bail along the rope."""

    name = "hoist_drive"
    params = ("K_H",)
    units = ("N/A",)
    description = "hoist motors' pull on the rope per ampere"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return _stack((-k.i_h * k.d * k.sin_a3, k.i_h * k.cos_a3))


@register_term
class CrowdDrive(Term):
    """Crowd force K_C * i_C along the handle."""

    name = "crowd_drive"
    params = ("K_C",)
    units = ("N/A",)
    description = "crowd motor's push on the handle per ampere"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return _stack((np.zeros_like(k.d), -k.i_c))


@register_term
class ArmInertia(Term):
    """Rotational inertia of the arm about the pivot, Izz + Md Lc^2."""

    name = "arm_inertia"
    params = ("J",)
    units = ("kg m^2",)
    description = "rotational inertia of the dipper and handle"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return _stack((k.thdd, np.zeros_like(k.thdd)))


@register_term
class Friction(Term):
    """Viscous and Coulomb friction on both joints (shipper shaft and crowd)."""

    name = "friction"
    params = ("fv3", "fc3", "fv4", "fc4")
    units = ("N m s/rad", "N m", "N s/m", "N")
    description = "friction in the handle rotation and the crowd"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.thd)
        return _stack((k.thd, z), (smooth_sign(k.thd, SIGN_EPS_TH), z),
                      (z, k.dd), (z, smooth_sign(k.dd, SIGN_EPS_D)))


BASE_TERMS: tuple[str, ...] = ("rigid_arm", "hoist_drive", "crowd_drive", "arm_inertia",
                               "friction")
"""The thesis's two-joint model; parameter order [Md, MdLc, K_H, K_C, J, fv3, fc3, fv4, fc4]."""
