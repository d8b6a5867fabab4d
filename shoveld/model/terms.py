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

import functools
import math
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


def _clip(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``np.clip`` for arrays without NaN (the same values): two ufuncs without its
    wrapper's checks, which on a block of ten rows cost several times the clipping."""
    return np.minimum(np.maximum(x, lo), hi)


def _sech(x: np.ndarray) -> np.ndarray:
    return 1.0 / np.cosh(_clip(x, -40.0, 40.0))  # (a NaN stays NaN, as with np.clip)


class Term:
    """One physical contribution to the equations of motion."""

    name: ClassVar[str]
    params: tuple[str, ...]
    """The term's parameters: a class's own, or an instance's (the hoist drive's knots)."""
    units: tuple[str, ...]
    description: ClassVar[str] = ""
    """What the term means, in words a field engineer uses."""
    base: ClassVar[bool] = False
    """True for the terms of the thesis's simplified model."""

    def __init__(self, **hyper: Any) -> None:
        self.hyper: dict[str, Any] = dict(hyper)

    @classmethod
    def file_hyper(cls, hyper: dict[str, Any]) -> dict[str, Any]:
        """The hyper-parameters a params file gives, with the value a key had before it
        was written (the term's form when the file was identified): as given here."""
        return hyper

    def columns(self, k: Kinematics) -> np.ndarray:
        """(N, 2, P): residual of [th, d] equations per unit of each parameter."""
        raise NotImplementedError

    def payload_columns(self, k: Kinematics) -> np.ndarray | None:
        """(N, 2, P) multiplied by the payload mass, or None when the term does not
        depend on the payload."""
        return None

    spread_params: ClassVar[tuple[str, ...]] = ()
    """Parameters whose columns the kinematics do not determine (see ``column_spread``)."""

    def column_spread(self, k: Kinematics) -> np.ndarray:
        """(N, 2, len(spread_params)): the standard deviation of those parameters' columns
        about their values."""
        return np.zeros((len(k), 2, 0))

    def current_derivative(self, k: Kinematics
                           ) -> tuple[np.ndarray | None, np.ndarray | None] | None:
        """Derivatives of the columns by the measured hoist and crowd currents, for terms
        linear in a measured current (None: the term does not use one; None for one of
        the two: its columns do not move with that current)."""
        return None

    def for_data(self, tables: list[Any]) -> Term:
        """The term with the hyper-parameters its data choose, from the tables' columns
        alone (knots at where the data lie), unless given; ``self`` when it has none.
        Called by ``Calibrator.fit`` before any fit (a hyper-parameter found by fits is
        ``search_hyper``'s job, ``shoveld.model.effects``)."""
        return self

    def transform(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Adjust the raw signals before kinematics (e.g. re-align a delayed stream).

        Receives and returns the signals-table columns; the default is identity.
        """
        return cols

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.hyper})" if self.hyper else type(self).__name__


_F8 = np.dtype(np.float64)


def pair(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """``np.stack([x, y], axis=axis)``: for two float64 arrays of one shape (1-D, or 2-D
    stacked on axis 1) the two copied into one new array, without ``np.stack``'s dozen
    Python-level calls (a payload block of ten rows makes eight of these); the same
    array, values and layout. Anything else goes to ``np.stack``."""
    if type(x) is np.ndarray and type(y) is np.ndarray and x.dtype == _F8 \
            and y.dtype == _F8 and x.shape == y.shape:
        if x.ndim == 1 and (axis == -1 or axis == 1):
            out = np.empty((x.shape[0], 2))
            out[:, 0] = x
            out[:, 1] = y
            return out
        if x.ndim == 2 and axis == 1:
            out = np.empty((x.shape[0], 2, x.shape[1]))
            out[:, 0] = x
            out[:, 1] = y
            return out
    return np.stack([x, y], axis=axis)


def _stack(*eqs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Columns given as (th_eq, d_eq) pairs -> (N, 2, P), float64 whatever the pairs' type
    (so the terms' zero columns are ``np.zeros(shape)``: ``np.zeros_like``'s Python
    wrapper cost several times the ten-row array, seven times a payload block)."""
    out = np.empty((len(eqs[0][0]), 2, len(eqs)))
    for j, (th_eq, d_eq) in enumerate(eqs):
        out[:, 0, j] = th_eq
        out[:, 1, j] = d_eq
    return out


def payload_phi(k: Kinematics) -> np.ndarray:
    """(N, 2): the payload as a point mass at the bail, per kilogram."""
    th_eq = k.d * k.d * k.thdd + 2.0 * k.d * k.dd * k.thd + k.d * G * np.cos(k.th)
    d_eq = k.ddd - k.d * k.thd * k.thd + G * np.sin(k.th)
    return pair(th_eq, d_eq)


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


def field_basis(i_f: np.ndarray, knots: tuple[float, ...], slope_above: bool = True,
                slope_below: bool = True, ends: str = "not-a-knot") -> np.ndarray:
    """(N, K) weights of the hoist field current on the knots of a smooth curve.

    Between knots: a cubic spline through the knot values (linear in them; a
    magnetisation curve is smooth, and straight segments 10 A long left 0.2-0.3 % of
    K_H unexplained between knots). Its ends are not-a-knot: a natural spline (no
    curvature at the end knots) on a Froehlich curve with knots 10 A apart is 0.24 %
    under it between the two lowest knots and 0.04 % near the top one, and the fit
    moved the knot values to make up for it; not-a-knot is within 0.02 %
    (docs/engine.md). ``ends="natural"`` is the curve of params files identified with
    it. Above the highest knot: along the curve's slope there for half a knot step,
    then constant (the iron is saturated). The highest knot
    is the nominal field rounded to an amp, and the field's noise spreads readings
    around it: a curve flat from the knot up left the readings above it at the knot's
    value and those below it lower, which biased K_H by +0.55 standard errors over 150
    simulated machines (−0.16 with the slope; docs/engine.md). ``slope_above=False``
    is that flat curve, for params files identified with it. Below the lowest knot, the
    same: along the curve's slope for half a knot step, then proportional to the field
    (unsaturated iron, flux ~ field current), the physical way out of the calibrated
    range. The lowest knot is the drive's minimum field, and noise puts half its
    readings below it; proportional from the knot down, those readings fell 0.7-1.5 %
    under the magnetisation curve and the lowest knot's value came out +1.4 standard
    errors high (docs/engine.md). ``slope_below=False`` is that curve, for params files
    identified with it.
    """
    kn = tuple(float(k) for k in knots)
    x = np.asarray(i_f, dtype=float)
    if not np.isfinite(x).all():  # (checked first: nan_to_num costs a block 6 us)
        x = np.nan_to_num(x, nan=kn[-1])
    if len(kn) == 1:
        out = np.ones((len(x), 1))
        out[:, 0] = np.where(x < kn[0], np.maximum(x, 0.0) / kn[0], 1.0)
        return out
    out = _spline_basis(kn, ends)(_clip(x, kn[0], kn[-1]))
    above = x > kn[-1]
    if slope_above and above.any():
        top, slope = _end_slope(kn, ends)
        step = np.minimum(x[above], kn[-1] + 0.5 * (kn[-1] - kn[-2])) - kn[-1]
        out[above] = top[None, :] + step[:, None] * slope[None, :]
    below = x < kn[0]
    if below.any() and slope_below:
        bottom, slope = _start_slope(kn, ends)
        x_b = kn[0] - 0.5 * (kn[1] - kn[0])
        step = np.maximum(x[below], x_b) - kn[0]
        # along the slope down to x_b, then proportional from the curve's value there
        at = bottom[None, :] + step[:, None] * slope[None, :]
        out[below] = at * np.where(x[below] < x_b, np.maximum(x[below], 0.0) / x_b, 1.0)[:, None]
    elif below.any():
        out[below, :] = 0.0
        out[below, 0] = np.maximum(x[below], 0.0) / kn[0]
    return out


@functools.cache
def _end_slope(kn: tuple[float, ...], ends: str) -> tuple[np.ndarray, np.ndarray]:
    """Weights of the curve's value and slope at the highest knot (the basis is a cubic
    on the last segment, so a one-sided difference over a millionth of it is exact to
    about that much)."""
    d = 1e-6 * (kn[-1] - kn[-2])
    rows = _spline_basis(kn, ends)(np.array([kn[-1], kn[-1] - d]))
    return rows[0], (rows[0] - rows[1]) / d


@functools.cache
def _start_slope(kn: tuple[float, ...], ends: str) -> tuple[np.ndarray, np.ndarray]:
    """Weights of the curve's value and slope at the lowest knot (as :func:`_end_slope`)."""
    d = 1e-6 * (kn[1] - kn[0])
    rows = _spline_basis(kn, ends)(np.array([kn[0], kn[0] + d]))
    return rows[0], (rows[1] - rows[0]) / d


@functools.cache
def _spline_basis(knots: tuple[float, ...], ends: str) -> Any:
    """The cubic spline through each unit vector of knot values."""
    return _CubicSpline(knots, ends) if len(knots) > 2 else _Linear(knots)


class _CubicSpline:
    """The cubic spline basis on numpy: row k of ``self(x)`` holds the weights of the
    knot values at x[k]. Natural ends (no curvature at the end knots) or not-a-knot
    (one cubic over the two end segments). scipy's ``CubicSpline`` with the same
    ``bc_type`` gives the same (``tests/engine/test_filters.py``); importing
    scipy.interpolate in the live daemon cost its loop 0.9 s at the first pass (py-spy,
    ``bench/daemon_live.py --profile``)."""

    def __init__(self, knots: tuple[float, ...], ends: str = "natural") -> None:
        x = np.asarray(knots, dtype=float)
        n = len(x)
        h = np.diff(x)
        # Second derivatives m = M y: the interior rows
        # h_{i-1} m_{i-1} + 2 (h_{i-1} + h_i) m_i + h_i m_{i+1} = 6 (slope diff),
        # and a row per end: m = 0 there (natural), or the third derivative continuous
        # across the first and last interior knots (not-a-knot).
        a = np.zeros((n, n))
        rhs = np.zeros((n, n))
        for i in range(1, n - 1):
            a[i, i - 1], a[i, i], a[i, i + 1] = h[i - 1], 2.0 * (h[i - 1] + h[i]), h[i]
            rhs[i, i - 1] += 6.0 / h[i - 1]
            rhs[i, i] -= 6.0 / h[i - 1] + 6.0 / h[i]
            rhs[i, i + 1] += 6.0 / h[i]
        if ends == "not-a-knot" and n > 3:
            a[0, :3] = h[1], -(h[0] + h[1]), h[0]
            a[-1, -3:] = h[-1], -(h[-2] + h[-1]), h[-2]
        elif ends == "not-a-knot":  # three knots: one parabola (as scipy's)
            a[0, :2] = 1.0, -1.0
            a[-1, -2:] = -1.0, 1.0
        else:
            a[0, 0] = a[-1, -1] = 1.0
        self.m = np.linalg.solve(a, rhs)
        self.x, self.h = x, h

    def __call__(self, xs: np.ndarray) -> np.ndarray:
        x, h, m = self.x, self.h, self.m
        i = _clip(np.searchsorted(x, xs, side="right") - 1, 0, len(x) - 2)
        hi = h[i]
        a = (x[i + 1] - xs) / hi
        b = 1.0 - a
        out = ((a ** 3 - a) * hi * hi / 6.0)[:, None] * m[i] + \
            ((b ** 3 - b) * hi * hi / 6.0)[:, None] * m[i + 1]
        rows = np.arange(len(xs))
        out[rows, i] += a
        out[rows, i + 1] += b
        return out


class _Linear:
    """Two knots: a straight line (a spline needs three)."""

    def __init__(self, knots: tuple[float, ...]) -> None:
        self.a, self.b = knots

    def __call__(self, x: np.ndarray) -> np.ndarray:
        f = (x - self.a) / (self.b - self.a)
        return pair(1.0 - f, f, axis=1)


BLOCK_ROWS = 64
"""Up to this many rows the hoist drive takes the field curve's weights row by row from
the readings it has seen (the live engine's blocks of ten); longer arrays (the
calibration's) in one evaluation."""
ROWS_KEPT = 4096
"""Field readings whose weights are kept (a 12-bit ADC channel reads no more codes)."""

FIELD_KNOT_PREFIX = "K_H_f"
"""Name of a field knot's parameter: the prefix, then the knot's field current (A)."""


def field_knot_a(name: str) -> float | None:
    """The field current of a field knot's parameter (``K_H_f30`` -> 30.0), else None."""
    return float(name[len(FIELD_KNOT_PREFIX):]) if name.startswith(FIELD_KNOT_PREFIX) else None


def knot_group(name: str) -> str:
    """Field knots by the nearest 10 A (``K_H_f29`` -> ``K_H_f30~``), other names as they
    are: the calibration places the knots where each machine's data have field
    currents, so statistics over machines by exact name would leave most out."""
    a = field_knot_a(name)
    return name if a is None else f"{FIELD_KNOT_PREFIX}{10 * round(a / 10):.0f}~"


FIELD_KNOT_STEP_A = 10.0
"""Spacing of the knots of the hoist's pull-per-ampere curve over the field current."""
FIELD_KNOT_MIN_SAMPLES = 150
"""Samples within half a step of a knot for the data to carry that knot."""


def choose_field_knots(tables: list[Any], step: float = FIELD_KNOT_STEP_A,
                       min_samples: int = FIELD_KNOT_MIN_SAMPLES) -> tuple[float, list[float]]:
    """The nominal hoisting field and the knots where the data have field currents.

    Nominal: the field the drive holds most of the time at speed (median of the upper
    field values). Knots every ``step`` amps below (and one above) it, kept where at
    least ``min_samples`` samples lie within half a step.
    """
    i_f = np.concatenate([t.columns["hoist_field_a"] for t in tables])
    i_f = i_f[np.isfinite(i_f)]
    if not len(i_f):
        return 70.0, []
    top = np.percentile(i_f, 95)
    nominal = float(np.round(np.median(i_f[i_f > 0.85 * top])))
    knots: list[float] = []
    for kn in [nominal + step, *(nominal - step * j for j in range(1, 10))]:
        if kn < 10.0:
            break
        if np.count_nonzero(np.abs(i_f - kn) < step / 2) >= min_samples:
            knots.append(float(kn))
    return nominal, sorted(knots)


@register_term
class HoistDrive(Term):
    """Hoist rope tension K_H(i_f) * i_H acting at the bail along the rope.

    A DC motor's pull per ampere is proportional to its flux, and the flux follows the
    field current along the motor's magnetisation curve; the drive weakens the field
    above base speed (hoisting fast, lowering). K_H(i_f) is a cubic spline
    (:func:`field_basis`) through knots of the field current (hyper-parameter
    ``field_knots_a``, chosen by the calibration where its data have field currents);
    its value at the nominal
    field is the parameter ``K_H``, at the other knots ``K_H_f<A>``. Linear in all of
    them, so the same least squares identifies the curve.
    """

    name = "hoist_drive"
    params: tuple[str, ...] = ("K_H",)  # and a parameter per knot (``__init__``)
    units: tuple[str, ...] = ("N per A",)
    description = "hoist motors' pull on the rope per ampere, over the hoist field current"
    base = True

    def __init__(self, **hyper: Any) -> None:
        super().__init__(**hyper)
        nominal = float(hyper.get("field_nominal_a", 70.0))
        knots = tuple(sorted({nominal, *(float(k) for k in hyper.get("field_knots_a", ()))}))
        self.knots = knots
        self.nominal_index = knots.index(nominal)
        self.params = tuple("K_H" if k == nominal else f"{FIELD_KNOT_PREFIX}{k:g}"
                            for k in knots)
        self.units = tuple("N per A" for _ in knots)
        self.uses_field_current = len(knots) > 1
        """Terms with this flag model the field: no sample is excluded for a weak field."""
        self.above = str(hyper.get("above_top_knot", "flat"))
        """How the curve goes on above the highest knot: ``slope`` (what the calibration
        writes since 2026-11-25), or ``flat`` (params files without the key)."""
        if self.above not in ("slope", "flat"):
            raise ValueError(f"hyper.hoist_drive.above_top_knot: expected 'slope' or "
                             f"'flat', got {self.above!r}")
        self.below = str(hyper.get("below_bottom_knot", "proportional"))
        """How the curve goes on below the lowest knot: ``slope`` (what the calibration
        writes now) or ``proportional`` (params files written before it)."""
        if self.below not in ("slope", "proportional"):
            raise ValueError(f"hyper.hoist_drive.below_bottom_knot: expected 'slope' or "
                             f"'proportional', got {self.below!r}")
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self._rows: dict[float, np.ndarray] = {}
        """The curve's weights of field readings seen in short blocks (``_block_basis``)."""
        self.ends = str(hyper.get("spline_ends", "natural"))
        """The spline's end condition: ``not-a-knot`` (what the calibration writes now) or
        ``natural`` (params files written before it)."""
        if self.ends not in ("not-a-knot", "natural"):
            raise ValueError(f"hyper.hoist_drive.spline_ends: expected 'not-a-knot' or "
                             f"'natural', got {self.ends!r}")

    def for_data(self, tables: list[Any]) -> Term:
        """The field-current knots where the tables have field currents
        (:func:`choose_field_knots`) and the curve's ends as the calibration writes them,
        unless given (knots given without the ends: the ends added)."""
        ends = {"above_top_knot": "slope", "below_bottom_knot": "slope",
                "spline_ends": "not-a-knot"}
        if "field_knots_a" in self.hyper:
            if ends.keys() <= self.hyper.keys():
                return self
            return type(self)(**{**ends, **self.hyper})
        nominal, knots = choose_field_knots(tables)
        return type(self)(**{**self.hyper, "field_nominal_a": nominal,
                             "field_knots_a": knots, **ends})

    def _basis(self, k: Kinematics) -> np.ndarray:
        """The curve's weights at ``k``'s field readings. The regressor and its current
        derivative both ask for them, for the same readings, once per block of the live
        engine (40 us each on ten rows): the last result is kept for the same array
        object (read only; no code writes into a field column in place)."""
        last = self._last
        if last is not None and last[0] is k.i_hf:
            return last[1]
        if len(self.knots) == 1:
            out = np.ones((len(k), 1))
        elif 0 < len(k) <= BLOCK_ROWS:
            out = self._block_basis(k.i_hf)
        else:
            out = self._field_basis(k.i_hf)
        self._last = (k.i_hf, out)
        return out

    def _field_basis(self, i_f: np.ndarray) -> np.ndarray:
        """The curve's weights at ``i_f``, evaluated (this term's curve settings)."""
        return field_basis(i_f, self.knots, self.above == "slope", self.below == "slope",
                           self.ends)

    def _block_basis(self, i_f: np.ndarray) -> np.ndarray:
        """:meth:`_field_basis` of a short block, row by row from the rows of the readings
        seen before. A block's readings repeat (the ADC is polled at half the loop's
        rate, and a steady field reads the same few codes), and the curve's 30 numpy
        operations cost a live block 40 us. ``field_basis`` works row by row, so a row
        depends only on its reading: the same weights. Not kept: NaN and infinite
        readings, and zero (whose sign can reach a weight's zero)."""
        rows = self._rows
        i_f = np.asarray(i_f, dtype=float)
        vals = i_f.tolist()
        todo = [i for i, v in enumerate(vals) if v not in rows]
        if not todo:
            return np.array([rows[v] for v in vals])
        fresh = dict(zip(todo, self._field_basis(i_f[todo]), strict=True))
        if len(rows) + len(todo) > ROWS_KEPT:
            rows.clear()
        for i, row in fresh.items():
            v = vals[i]
            if v != 0.0 and math.isfinite(v):
                rows[v] = row.copy()  # (not a view: it would keep its block's array)
        return np.array([fresh[i] if i in fresh else rows[v] for i, v in enumerate(vals)])

    def columns(self, k: Kinematics) -> np.ndarray:
        return self.current_columns(k, k.i_h)

    def current_columns(self, k: Kinematics, i_h: np.ndarray | float) -> np.ndarray:
        """The columns per unit of ``i_h`` (pass ones for the derivative by the current)."""
        h = self._basis(k)
        u_th = -k.d * k.sin_a3 * i_h
        u_d = k.cos_a3 * i_h
        return pair(u_th[:, None] * h, u_d[:, None] * h, axis=1)

    def current_derivative(self, k: Kinematics) -> tuple[np.ndarray, None]:
        """d(columns)/d(i_H); the crowd current does not move them."""
        return self.current_columns(k, np.ones(len(k))), None


@register_term
class CrowdDrive(Term):
    """Crowd force K_C * i_C along the handle."""

    name = "crowd_drive"
    params = ("K_C",)
    units = ("N per A",)
    description = "crowd motor's push on the handle per ampere"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return _stack((np.zeros(k.d.shape), -k.i_c))

    def current_derivative(self, k: Kinematics) -> tuple[None, np.ndarray]:
        """d(columns)/d(i_C); the hoist current does not move them."""
        z = np.zeros(k.d.shape)
        return None, _stack((z, -np.ones(z.shape)))


@register_term
class ArmInertia(Term):
    """Rotational inertia of the arm about the pivot, Izz + Md Lc^2."""

    name = "arm_inertia"
    params = ("J",)
    units = ("kg m^2",)
    description = "rotational inertia of the dipper and handle"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return _stack((k.thdd, np.zeros(k.thdd.shape)))


@register_term
class Friction(Term):
    """Viscous and Coulomb friction on both joints (shipper shaft and crowd)."""

    name = "friction"
    params = ("fv3", "fc3", "fv4", "fc4")
    units = ("N m s/rad", "N m", "N s/m", "N")
    description = "friction in the handle rotation and the crowd"
    base = True

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros(k.thd.shape)
        return _stack((k.thd, z), (smooth_sign(k.thd, SIGN_EPS_TH), z),
                      (z, k.dd), (z, smooth_sign(k.dd, SIGN_EPS_D)))

    spread_params = ("fc3", "fc4")

    def column_spread(self, k: Kinematics) -> np.ndarray:
        """Near standstill the Coulomb friction's sign is not known: real friction
        (stiction, the Stribeck dip, pre-sliding) and a rate estimated from noisy angles
        both leave it anywhere between -fc and +fc. Read the smoothed sign tanh(v / eps)
        as the sign's expected value; a sign of +-1 with that mean has standard deviation
        sech(v / eps), 1 at standstill and under 0.04 beyond four widths."""
        z = np.zeros(k.thd.shape)
        return _stack((_sech(k.thd / SIGN_EPS_TH), z), (z, _sech(k.dd / SIGN_EPS_D)))


@register_term
class CurrentOffsets(Term):
    """Zero offsets of the hoist (sum of both motors) and crowd current transducers.

    A Hall-effect transducer reads a few amps with no current; the offset belongs to
    the installation. It lives on the measurement side, not in the dynamics: the
    current equations (``shoveld.model.output``) compare measured minus offset with
    the current the model predicts. In force units its columns are zero.
    """

    name = "current_offsets"
    params = ("i_H0", "i_C0")
    units = ("A", "A")
    description = "zero offsets of the hoist and crowd current sensors"
    base = True
    output_offsets = True

    def columns(self, k: Kinematics) -> np.ndarray:
        return np.zeros((len(k), 2, 2))


BASE_TERMS: tuple[str, ...] = ("rigid_arm", "hoist_drive", "crowd_drive", "arm_inertia",
                               "friction", "current_offsets")
"""The thesis's two-joint model with the hoist's pull per ampere over the field current
and the current sensors' offsets; parameter order [Md, MdLc, K_H (K_H_f<A> ...), K_C, J,
fv3, fc3, fv4, fc4, i_H0, i_C0]."""
