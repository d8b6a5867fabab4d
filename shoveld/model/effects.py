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

from shoveld.model.geometry import L_BS, G, rope_geometry
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
    needs_swing: ClassVar[bool] = False
    """Only swinging excites the term (calibration trials usually do not swing)."""
    needs_full_dipper: ClassVar[bool] = False
    """Only the currents of a full dipper excite the term (the trials' loads stay lower):
    it is identified with the verified passes too, cross-validated."""
    residual_blind: ClassVar[bool] = False
    """Over a shovel's working range the term's columns are nearly a combination of the
    base model's: identification moves the base's own parameters to absorb it (the rope's
    weight grows with the reach as the dipper's does), so the held-out residual barely
    changes either way and the payload is its only witness. The selection may name such
    a term on the payload alone (``SelectionConfig.blind_z``)."""
    masked_by: ClassVar[tuple[str, ...]] = ()
    """Terms beside which this one's residual signature is nearly the other's: once one of
    them is in the model the residual cannot judge this term, and the selection may name
    it on the payload as a ``residual_blind`` term, whatever share of the residual it
    takes (``SelectionConfig.blind_z``)."""
    aligns_streams: ClassVar[bool] = False
    """The term moves the data, not the model: it re-aligns sensor streams in time
    (``transform``), so every other term fitted on the streams out of step is distorted
    by them; the selection adds it first when it takes a decisive share
    (``SelectionConfig.align_first``)."""
    per_load: ClassVar[bool] = False
    """The term acts per kilogram of load (payload columns only): its signal on a pass
    grows with the load, and the selection weights the passes so when it tests it
    (``SelectionConfig.load_weighted``)."""
    predicted: ClassVar[dict[str, tuple[str, float, float]]] = {}
    """Own parameter -> (base parameter, lo, hi): physics predicts the ratio of the two
    (the slope's K_H_pitch is K_H when the deck's pitch is the ground's), and a fit whose
    ratio lies in [lo, hi], clear of zero, confirms the cause: the selection may name the
    term on the payload as one that is masked, whatever share of the residual it takes
    (``select._confirmed``)."""
    bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    """Physically admissible range of an own parameter (a mass per metre is not negative):
    a value outside it says the term stands in for another cause."""
    search: ClassVar[dict[str, tuple[float, float]]] = {}
    """Hyper-parameters found by a 1-D search on training data, with their bounds."""
    defaults: ClassVar[dict[str, float | str]] = {}
    cause: ClassVar[str] = ""
    """The physical cause in the words of a field engineer (the report's headline)."""
    signature: ClassVar[str] = ""
    """The variable the residual should be plotted against to see this cause."""

    search_tol: ClassVar[dict[str, float]] = {}
    search_step: ClassVar[dict[str, float]] = {}
    """Central differences of the profile for a searched value's standard error
    (``_refine``; a twentieth of the bounds unless given)."""
    model_error: ClassVar[dict[str, float]] = {}
    """Per physical value (by its wording in ``quantities`` or ``searched``): the error the
    fit's own uncertainty does not show, added to it in quadrature (a type B uncertainty:
    the base model's misfit of a machine pulls the value the same way in all its data).
    Measured on simulated realistic machines (``bench/findings_coverage.py``: the value
    that makes the RMS of error over standard deviation one on one set of machines,
    checked on another)."""

    def __init__(self, **hyper: Any) -> None:
        super().__init__(**{**self.defaults, **hyper})
        self.given: set[str] = set(hyper)
        """Hyper-parameters fixed by the caller (a params file, the diagnosis): not searched."""

    def h(self, name: str) -> float:
        return float(self.hyper[name])

    def search_hyper(self, cal: Any, tables: list[Any]) -> None:
        """Find each hyper-parameter of ``search`` that was not given, and its standard
        error (kept beside it in ``hyper``: ``std_key``).

        Brent's bounded 1-D search over the profile of the thesis's equation-error fit
        of the calibrator ``cal`` on ``tables`` (``_profile_point``: the parameters
        refitted at each trial value, a tenth of the output-error fit's cost); the
        objective is the fit's residual, per equation in units of the first trial's, so
        both equations count. Then the minimum of the profile of ``cal``'s own fit
        near there, and its standard error (``_refine``: three to six fits). Called by
        ``Calibrator.fit`` before it fits; afterwards the value counts as given. A flat
        objective (no swing in the data) keeps the default: the data cannot tell.
        """
        from scipy.optimize import minimize_scalar

        for name, (lo, hi) in self.search.items():
            if name in self.given:
                continue
            self.given.add(name)  # the inner fits keep the trial value
            scale: list[np.ndarray] = []
            tried: dict[float, float] = {}

            def objective(v: float, name: str = name, scale: list[np.ndarray] = scale,
                          tried: dict[float, float] = tried) -> float:
                self.hyper[name] = float(v)
                tried[float(v)] = _profile_point(cal, tables, scale)[1]
                return tried[float(v)]

            start = self.h(name)
            objective(start)
            minimize_scalar(objective, bounds=(lo, hi), method="bounded",
                            options={"xatol": self.search_tol.get(name, (hi - lo) / 200)})
            if max(tried.values()) - min(tried.values()) <= 1e-9:
                self.hyper[name] = start
                continue
            self.hyper[name] = min(tried, key=tried.__getitem__)
            _, self.hyper[self.std_key(name)] = _refine(
                self, cal, tables, name, self.search_step.get(name, (hi - lo) / 20))

    @staticmethod
    def std_key(name: str) -> str:
        """Where ``hyper`` keeps a searched value's standard error: R0_m -> R0_std_m."""
        head, _, unit = name.rpartition("_")
        return f"{head}_std_{unit}" if head else f"{name}_std"

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        """Physical quantities implied by the identified parameters (for the report)."""
        return {}

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        """(what, unit, value from the identified parameters): the physical values a field
        engineer can check against the machine (``findings`` adds their uncertainty)."""
        return []

    def findings(self, names: list[str], values: np.ndarray, cov: np.ndarray
                 ) -> list[dict[str, Any]]:
        """Each of ``quantities`` with its standard deviation by the delta method (a
        numerical gradient through the parameters' covariance), and each searched
        hyper-parameter with its search's; ``std`` adds the value's ``model_error``
        (``std_fit`` is the data's part alone)."""
        found: list[tuple[str, str, float, float]] = []
        base = dict(zip(names, (float(v) for v in values), strict=True))
        for what, unit, fn in self.quantities():
            v0 = fn(base)
            grad = np.zeros(len(names))
            for j, n in enumerate(names):
                h = 1e-6 * max(abs(base[n]), 1e-3)
                grad[j] = (fn({**base, n: base[n] + h}) - v0) / h
            found.append((what, unit, v0, math.sqrt(max(0.0, float(grad @ cov @ grad)))))
        found += self.searched()
        return [{"what": what, "value": value, "unit": unit, "std_fit": std,
                 "std": math.hypot(std, self.error_of(what))}
                for what, unit, value, std in found]

    def error_of(self, what: str) -> float:
        """The model error of the physical value worded ``what`` (``model_error``)."""
        return self.model_error.get(what, 0.0)

    def searched(self) -> list[tuple[str, str, float, float]]:
        """(what, unit, value, resolution) of hyper-parameters found by a search."""
        return []


@register_term
class HoistFieldWeakening(ExtensionTerm):
    """K_H follows the hoist field current through the magnetisation curve.

    A DC motor's pull per ampere is proportional to its flux, and the flux follows the
    field current along the magnetisation curve. Around the nominal hoisting field i0
    the curve is written by its slope: K_H(i_f) = K_H + K_Hf1 (i_f / i0 - 1), so the
    column is the rope-tension column times (i_f / i0 - 1), linear in K_Hf1.

    Only the hoisting range is modelled: the lowering field (~30 A) stays excluded as
    in the base model. A global curve (a cubic over 30-80 A) was tried and rejected:
    the data sit in two clusters (lowering, hoisting) with fast transitions between,
    and 0.3 A of field noise already bends a cubic enough to spoil the slope at 70 A
    that lift and swing depend on. The column uses the current estimated from the
    neighbouring samples, so its noise does not correlate with the current on the
    other side of the equation.
    """

    name = "hoist_field_weakening"
    params = ("K_Hf1",)
    units = ("N per A",)
    description = "hoist force per ampere changing with the hoist field current"
    cause = ("the hoist motors' pull per ampere changes with the hoist field current "
             "(field forcing or weakening, magnetic saturation of the field)")
    signature = "hoist_field_a"
    defaults = {"field_nominal_a": 70.0}
    static_params = ("K_Hf1",)

    def columns(self, k: Kinematics) -> np.ndarray:
        x = k.i_hf / self.h("field_nominal_a") - 1.0
        u_th, u_d = _unit_hoist(k)
        assert k.i_h_est is not None  # Kinematics.__post_init__ sets it
        q = k.i_h_est * x
        return _stack((q * u_th, q * u_d))

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"flux slope d(K_H/K_H0)/d(i_f/i_f0)": values["K_Hf1"] / values["K_H"]}

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [("hoist pull per ampere change per unit of relative field", "",
                 lambda v: v["K_Hf1"] / v["K_H"])]


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
    slender body (its width), and R0 is found by a search on the fit's residual
    (``ExtensionTerm.search_hyper``).

    The search was an alternation of fits and Gauss-Newton steps in R0 until
    2026-11-28: on 5 of 10 realistic machines it ran to the bound 0 m (true radii
    3-5.6 m), while the output-error fit's residual has its minimum within 0.04 m of
    the truth on all ten (docs/diagnosis.md, seventeenth session).
    """

    name = "swing_centrifugal"
    params = ("dJ_sw",)
    units = ("kg m^2",)
    description = "centrifugal forces while swinging"
    cause = ("swinging throws the dipper outward: the centrifugal pull of the turning "
             "arm and load loads the hoist and crowd")
    signature = "swing_rate"
    needs_swing = True
    defaults = {"R0_m": 4.5}
    search = {"R0_m": (0.0, 9.0)}
    search_tol = {"R0_m": 0.3}
    # the residual is nearly linear in R0, so its profile is nearly quadratic over a metre
    search_step = {"R0_m": 1.0}

    def _w2(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return k.swing_rate**2, np.cos(k.th), np.sin(k.th)

    RADIUS: ClassVar[str] = "swing axis to shipper shaft (radius of the arm's turn)"
    # Measured on 20 realistic machines (bench/findings_coverage.py, seed offset 5000:
    # 0.018 m makes the RMS of error over standard deviation one); on 20 others (9000)
    # the RMS is then 1.13, 18/20 within two (docs/diagnosis.md, seventeenth session).
    model_error = {RADIUS: 0.02}

    def searched(self) -> list[tuple[str, str, float, float]]:
        # the search's standard error (``_refine``); a radius given, or one whose profile
        # has no curvature there, has only the search's tolerance
        std = float(self.hyper.get(self.std_key("R0_m"), math.nan))
        return [(self.RADIUS, "m", self.h("R0_m"),
                 std if math.isfinite(std) else self.search_tol["R0_m"])]

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


MTI_STREAM = ("handle_deg", "swing_deg")
"""Signals of the MTi: the handle's angle and the house's swing."""
LASER_STREAM = ("crowd_m",)
"""Signal of the laser: the handle's extension."""
DRIVE_STREAM = ("hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a", "crowd_field_a", "swing_a",
                "swing_field_a", "boom_deg", "roll_deg", "pitch_deg")
"""Signals of the analog logger (Hall-effect current sensors and inclinometers)."""


def _delay_columns(t: np.ndarray, cols: dict[str, np.ndarray], names: tuple[str, ...],
                   delay: float) -> None:
    """x(t) <- x(t - delay), taken from the nearest sample (NaN where none is near).

    Whole samples, not interpolation: interpolating between samples would average
    their noise and make a fractional delay look better than it is.
    """
    dt = float(np.median(np.diff(t)))
    want = t - delay
    j = np.clip(np.searchsorted(t, want), 1, len(t) - 1)
    j = np.where(np.abs(t[j - 1] - want) <= np.abs(t[j] - want), j - 1, j)
    near = np.abs(t[j] - want) <= 0.5 * dt
    for n in names:
        cols[n] = np.where(near, cols[n][j], np.nan)


class StreamDelay:
    """Causal delay line for some fields of a ``Sample`` (live twin of the transform)."""

    def __init__(self, names: tuple[str, ...], delay_s: float) -> None:
        self.names = names
        self.delay = delay_s
        self.buf: deque[tuple[float, tuple[float, ...]]] = deque()
        self.dt = 0.0
        """The latest sample interval (0 until there are two samples)."""

    def __call__(self, s: Any) -> Any:
        t = s.time_s
        self.buf.append((t, tuple(getattr(s, n) for n in self.names)))
        want = t - self.delay
        while len(self.buf) >= 2 and abs(self.buf[1][0] - want) <= abs(self.buf[0][0] - want):
            self.buf.popleft()
        t0, v0 = self.buf[0]
        if len(self.buf) > 1:
            self.dt = (self.buf[-1][0] - self.buf[-2][0])
        if abs(t0 - want) > 0.5 * self.dt + 1e-9:
            v0 = tuple(math.nan for _ in self.names)
        return replace(s, **dict(zip(self.names, v0, strict=True)))


class StreamDelays:
    """Several delay lines in turn (one per late group of fields)."""

    def __init__(self, lines: list[StreamDelay]) -> None:
        self.lines = lines

    def __call__(self, s: Any) -> Any:
        for line in self.lines:
            s = line(s)
        return s


@register_term
class SensorTimeSkew(ExtensionTerm):
    """One sensor stream is late against the others.

    Three devices sample the machine, each with its own buffering: the MTi on the
    saddle block (handle angle, swing), the laser beside it (crowd extension) and the
    analog logger of currents and inclinometers. ``delay_s`` is how much older the
    MTi's readings are than the currents (negative: the currents are the older);
    ``crowd_lag_s`` is how much older the laser's are than the MTi's, 0 when the two
    arm devices report in step (one arm-geometry stream). The transform re-aligns the
    streams by delaying the leading ones by whole samples (causal, so the live engine
    does the same with delay lines). Both are found by a search over whole samples.
    """

    name = "sensor_time_skew"
    params = ()
    units = ()
    description = "arm sensor and current logger out of step"
    cause = ("the arm-position sensors and the current logger are out of step in time "
             "(one sensor stream is delayed)")
    signature = "time_shift"
    aligns_streams = True
    defaults = {"delay_s": 0.0, "crowd_lag_s": 0.0}
    search = {"delay_s": (-0.3, 0.3), "crowd_lag_s": (-0.3, 0.3)}
    model_error_s: ClassVar[dict[str, float]] = {"mti": 0.0115, "laser": 0.0174}
    """Each device's delay error that the trials' own scatter does not show (a type B
    uncertainty, added in quadrature to the search's standard error): the base model's
    misfit of a machine pulls the delay the same way in every block of its trials.
    Measured on the detection matrix's 53 time-skew cases (realistic machines): the
    value that makes the RMS of error over standard deviation one there
    (``bench/delay_uncertainty.py --cases bench``; checked on new machines with
    ``--cases fresh``, docs/diagnosis.md)."""

    def columns(self, k: Kinematics) -> np.ndarray:
        return np.zeros((len(k), 2, 0))

    def lateness(self) -> dict[tuple[str, ...], float]:
        """Each device's signals and how much older its readings are than the currents."""
        d = self.h("delay_s")
        return {DRIVE_STREAM: 0.0, MTI_STREAM: d, LASER_STREAM: d + self.h("crowd_lag_s")}

    def searched(self) -> list[tuple[str, str, float, float]]:
        late = self.lateness()
        # each device's standard error as the search found it (``_delay_errors``; a
        # delay given, or one whose objective has no curvature, has only its resolution);
        # ``findings`` adds the model's error (``error_of``)
        return [(f"{device} stream ({signals}) late against the currents" if late[names] >= 0
                 else f"current stream late against the {device}", "s", abs(late[names]),
                 float(self.hyper.get(f"{key}_late_std_s", 0.01)))
                for names, device, key, signals in (
                    (MTI_STREAM, "MTi", "mti", "handle angle, swing"),
                    (LASER_STREAM, "laser", "laser", "crowd"))]

    def error_of(self, what: str) -> float:
        """Each device's delay has its own model error (``model_error_s``); the wording
        of its value names the device."""
        return self.model_error_s["laser" if "laser" in what else "mti"]

    def _delays(self) -> list[tuple[tuple[str, ...], float]]:
        """(signals, delay) that bring every stream to the latest one's time."""
        late = self.lateness()
        last = max(late.values())
        return [(names, last - d) for names, d in late.items() if last - d > 0.0]

    def transform(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        delays = self._delays()
        if not delays:
            return cols
        out = dict(cols)
        t = np.asarray(cols["time_s"])
        for names, delay in delays:
            _delay_columns(t, out, names, delay)
        return out

    def stream(self) -> Callable[[Any], Any] | None:
        """The live version of ``transform``: causal delay lines on samples."""
        delays = self._delays()
        return StreamDelays([StreamDelay(n, d) for n, d in delays]) if delays else None

    def search_hyper(self, cal: Any, tables: list[Any]) -> None:
        """Delays in whole samples: start where the residual points (to first order a
        delay tau leaves tau x dI/dt in the hoist current), walk the arm's delay sample
        by sample downhill on the fit's residual, then both delays together (the laser's
        own, and the MTi's with the laser's held), in steps of 4, 2 and 1 samples."""
        if "delay_s" in self.given and "crowd_lag_s" in self.given:
            return
        free = {n for n in ("delay_s", "crowd_lag_s") if n not in self.given}
        self.given |= free
        dt = 1.0 / float(tables[0].sample_rate_hz)
        lo, hi = self.search["delay_s"]
        kmax = int(min(-lo, hi) / dt)
        lo, hi = self.search["crowd_lag_s"]
        jmax = int(min(-lo, hi) / dt)
        k0 = int(round(self.h("delay_s") / dt))
        j0 = int(round(self.h("crowd_lag_s") / dt))
        tried: dict[tuple[int, int], float] = {}
        parts: dict[tuple[int, int], dict[int, float]] = {}
        scale: list[np.ndarray] = []
        first: list[Any] = []

        def ok(k: int, j: int) -> bool:
            # each device within the delay's bounds of the currents, and of the other
            return (abs(k) <= kmax and abs(k + j) <= kmax and abs(j) <= jmax
                    and ("delay_s" in free or k == k0) and ("crowd_lag_s" in free or j == j0))

        def objective(kj: tuple[int, int]) -> float:
            if kj not in tried:
                self.hyper["delay_s"] = kj[0] * dt
                self.hyper["crowd_lag_s"] = kj[1] * dt
                inner, tried[kj], parts[kj] = _profile_point(cal, tables, scale)
                if not first:
                    first.append(inner)
            return tried[kj]

        def walk(here: tuple[int, int], moves: list[tuple[int, int]]) -> tuple[int, int]:
            while True:
                nxt = [(here[0] + a, here[1] + b) for a, b in moves]
                better = [kj for kj in nxt if ok(*kj) and objective(kj) < objective(here)]
                if not better:
                    return here
                here = min(better, key=objective)

        here = (k0, j0)
        objective(here)
        if "delay_s" in free:
            k = int(np.clip(round(self._implied_delay(first[0]) / dt), -kmax, kmax))
            here = walk((k, j0), [(-1, 0), (1, 0)])
        for step in (4, 2, 1):
            # the laser alone, the MTi alone, both arm devices together
            here = walk(here, [(0, -step), (0, step), (-step, step), (step, -step),
                               (-step, 0), (step, 0)])
        best = min(tried, key=tried.__getitem__)
        std = _delay_errors(best, objective, parts, ok, free)
        self.hyper["delay_s"] = best[0] * dt
        self.hyper["crowd_lag_s"] = best[1] * dt
        # kept with the delays (the params file's [hyper], the later steps' fixed values)
        for key, s in zip(("mti", "laser"), std, strict=True):
            self.hyper[f"{key}_late_std_s"] = (math.sqrt(s**2 + 1.0 / 12.0) * dt
                                               if math.isfinite(s) else 0.5 * dt)

    @staticmethod
    def _implied_delay(cal: Any) -> float:
        """Slope of the hoist current residual on the rate of change of the current."""
        p = cal.params_
        num = den = 0.0
        for f in cal.files_:
            sel = f.use
            if sel.sum() < 10:
                continue
            k = f.kin.take(sel)
            e = cal.model.residual(k, p.values, f.payload[sel])[:, 0]
            r = e / (-p.get("K_H") * k.d * k.sin_a3)
            di = np.gradient(k.i_h_est, k.t)
            ok = np.isfinite(r) & np.isfinite(di) & (np.diff(k.t, prepend=k.t[0]) < 0.1)
            num += float(np.sum(r[ok] * di[ok]))
            den += float(np.sum(di[ok] ** 2))
        return num / den if den > 0 else 0.0


DELAY_BLOCK_S = 4.0
"""Blocks of the trials over which the delay search's scores are summed (as the
output-error fit's covariance sums its scores: ``output_error.BLOCK_S``)."""


def _block_shares(cal: Any, scale: np.ndarray) -> dict[int, float]:
    """The search's objective (each equation's or channel's mean squared residual in
    units of its first value) split over blocks of ``DELAY_BLOCK_S`` seconds of each
    file: its shares sum to the objective. Blocks are counted from each file's first
    sample, so the same block holds the same stretch of the trial whatever the value."""
    r = cal.row_residuals_
    files = [f for f in cal.files_ if f.use.any()]
    ids = np.concatenate([i * 1_000_000 + np.floor((f.kin.t[f.use] - f.kin.t[0]) / DELAY_BLOCK_S)
                          for i, f in enumerate(files)]).astype(np.int64)
    used = np.isfinite(r)
    per_row = np.sum(np.where(used, r, 0.0) ** 2
                     / (scale[None, :] ** 2 * np.maximum(used.sum(axis=0), 1)[None, :]), axis=1)
    keys, inv = np.unique(ids, return_inverse=True)
    sums = np.bincount(inv, weights=per_row)
    return dict(zip(keys.tolist(), sums.tolist(), strict=True))


def _sandwich(h: np.ndarray, g: np.ndarray) -> np.ndarray | None:
    """V = H^-1 B H^-1: the covariance of an M-estimator whose objective is a sum over
    blocks, from the sum's curvature ``h`` (p x p) and each block's gradient ``g``
    (n x p), B the gradients' covariance (centred: at the minimum of the sum they sum to
    zero, and a grid's rounding or another method's minimum leaves a common part that is
    no scatter). None when fewer than 3 blocks or the curvature is not positive (the
    data do not hold the value)."""
    n = len(g)
    if n < 3 or np.any(np.linalg.eigvalsh(h) <= 0):
        return None
    g = g - g.mean(axis=0)
    hinv = np.linalg.inv(h)
    return hinv @ (g.T @ g * n / (n - 1)) @ hinv


def _profile_point(cal: Any, tables: list[Any], scale: list[np.ndarray],
                   method: str = "equation") -> tuple[Any, float, dict[int, float]]:
    """One point of a search's profile: the fit of ``cal`` on ``tables`` in ``method``'s
    form at the hyper-parameters as they stand, its objective (each equation's mean
    squared residual - the output-error form's: each current's - in units of the first
    point's, which ``scale`` keeps) and the objective's shares over blocks
    (``_block_shares``). The thesis's equation-error form is a tenth of the output-error
    fit's cost."""
    import copy

    inner = copy.copy(cal)
    inner.method = method
    inner.fit(tables)
    fit = inner.params_.fit
    rms = np.array(list((fit["current_residual_rms_a"] if method == "output"
                         else fit["residual_rms"]).values()))
    if not scale:
        scale.append(rms)
    return inner, float(np.sum((rms / scale[0]) ** 2)), _block_shares(inner, scale[0])


def _parabola(step: float, s: list[float], parts: list[dict[int, float]]
              ) -> tuple[float, float]:
    """From a profile at x0, x0 + step, x0 - step (objectives ``s``, block shares
    ``parts``): the parabola's vertex less x0, and the sandwich's standard error of the
    minimum (``_sandwich``), each block's gradient taken at the vertex from the block's
    own parabola (exact for quadratic blocks, wherever x0 lies); NaN, NaN where the
    curvature is not positive."""
    curv = (s[1] + s[2] - 2.0 * s[0]) / step**2
    if not curv > 0.0:
        return math.nan, math.nan
    dx = -(s[1] - s[2]) / (2.0 * step) / curv
    blocks = sorted(set().union(*parts))
    p0, p1, p2 = (np.array([p.get(b, 0.0) for b in blocks]) for p in parts)
    g = (p1 - p2) / (2.0 * step) + (p1 + p2 - 2.0 * p0) / step**2 * dx
    v = _sandwich(np.array([[curv]]), g[:, None])
    return dx, math.sqrt(v[0, 0]) if v is not None else math.nan


def _refine(term: ExtensionTerm, cal: Any, tables: list[Any], name: str, step: float
            ) -> tuple[float, float]:
    """The minimum of the profile of ``cal``'s own fit (its ``method``) near the value the
    search found, and its standard error: the vertex of the parabola through the
    profile at the value and +- ``step``, re-centred once if the vertex lies beyond a
    step. On ten realistic machines the output-error fit's profile has its minimum
    within 0.04 m of the true swing radius where the equation-error form's was up to
    0.94 m off (docs/diagnosis.md, seventeenth session)."""
    lo, hi = term.search[name]
    x, std = term.h(name), math.nan
    scale: list[np.ndarray] = []
    for _ in range(2):
        x0 = float(np.clip(x, lo + step, hi - step))
        s: list[float] = []
        parts: list[dict[int, float]] = []
        for xi in (x0, x0 + step, x0 - step):
            term.hyper[name] = xi
            _, s_i, p_i = _profile_point(cal, tables, scale, cal.method)
            s.append(s_i)
            parts.append(p_i)
        dx, std = _parabola(step, s, parts)
        if not math.isfinite(dx):
            break
        x = float(np.clip(x0 + dx, lo, hi))
        if abs(dx) <= step:
            break
    term.hyper[name] = x
    return x, std


def _delay_errors(best: tuple[int, int], objective: Callable[[tuple[int, int]], float],
                  parts: dict[tuple[int, int], dict[int, float]],
                  ok: Callable[[int, int], bool], free: set[str]) -> tuple[float, float]:
    """Standard errors, in samples, of the MTi's and the laser's lateness found by the
    search: the sandwich of an M-estimator over blocks of the trials.

    The delays minimise a sum over blocks of S_b(k, j), the parameters refitted at each
    delay (a profile). A block's change of S_b across the best point is its score (with
    the parameters profiled out, exactly the efficient score), and the scores' spread
    between blocks - the misfit of the causes not modelled, of the machine, the noise,
    each block on its own - is what moves the delay; the curvature of the sum turns it
    into the delay's: V = H^-1 B H^-1 with B the blocks' centred scores' covariance.
    Central differences at one sample (the profile is evaluated there anyway by the
    walk's last step). NaN where a neighbour lies outside the bounds or the curvature is
    not positive (the data do not hold the delay)."""
    k, j = best
    dims = [d for d, name in (((1, 0), "delay_s"), ((0, 1), "crowd_lag_s")) if name in free]
    if not dims:
        return math.nan, math.nan
    pts = [(k + a * s, j + b * s) for a, b in dims for s in (1, -1)]
    if len(dims) == 2:
        pts += [(k + 1, j - 1), (k - 1, j + 1)]
    if not all(ok(*p) for p in pts):
        return math.nan, math.nan
    s0 = objective(best)
    h_diag = [objective((k + a, j + b)) + objective((k - a, j - b)) - 2 * s0 for a, b in dims]
    h = np.diag(h_diag)
    if len(dims) == 2:
        anti = objective((k + 1, j - 1)) + objective((k - 1, j + 1)) - 2 * s0
        h[0, 1] = h[1, 0] = 0.5 * (h_diag[0] + h_diag[1] - anti)
    blocks = sorted(set().union(*(parts[p] for p in pts[:2 * len(dims)])))
    g = np.array([[0.5 * (parts[(k + a, j + b)].get(i, 0.0)
                          - parts[(k - a, j - b)].get(i, 0.0)) for a, b in dims]
                  for i in blocks])
    v = _sandwich(h, g)
    if v is None:
        return math.nan, math.nan
    # the lateness of each device: the MTi's is delay_s, the laser's delay_s + crowd_lag_s
    full = np.zeros((2, 2))
    idx = [0 if d == (1, 0) else 1 for d in dims]
    full[np.ix_(idx, idx)] = v
    return (math.sqrt(full[0, 0]) if "delay_s" in free else math.nan,
            math.sqrt(max(0.0, full[0, 0] + full[1, 1] + 2 * full[0, 1])))


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
    per_load = True
    # the load lies in the dipper's bowl: in front of the bail pin and below it
    bounds = {"cog_fwd": (0.0, math.inf), "cog_up": (-math.inf, 0.0)}

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((z, z), (z, z))

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [("load centre of gravity in front of the bail (along the handle)", "m",
                 lambda v: v["cog_fwd"]),
                ("load centre of gravity below the bail (across the handle)", "m",
                 lambda v: -v["cog_up"])]

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
    lam g [dl/dq (y_B + y_P) / 2 + l / 2 dy_P/dq] - (lam g y_D) dl/dq. Linear in lam;
    the last part is a constant rope tension, which the base model's hoist current
    offset already carries (a second column for it would be the offset's twin and
    leave both unidentifiable).
    """

    name = "hoist_rope_mass"
    params = ("rope_kg_m",)
    units = ("kg/m",)
    description = "weight of the hoist rope"
    cause = ("the hoist rope's own weight between the boom-point sheave and the bail "
             "is carried by the hoist")
    signature = "rope_length"
    static_params = ("rope_kg_m",)
    # On the realistic bench the true rope (88-166 kg/m, 7-45 standard errors) took -1.4
    # to +3 % of the residual after another term, and halved the payload error
    # (docs/diagnosis.md): its weight is the dipper's weight moved along the rope.
    residual_blind = True
    bounds = {"rope_kg_m": (0.0, math.inf)}

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [("hoist rope mass (both ropes)", "kg/m", lambda v: v["rope_kg_m"])]

    def columns(self, k: Kinematics) -> np.ndarray:
        u_th, u_d = _unit_hoist(k)
        s = np.sin(k.th)
        ymid = 0.5 * (L_BS * np.sin(k.boom) + k.d * s)
        lam = (G * (u_th * ymid + 0.5 * k.l_sd * k.d * np.cos(k.th)),
               G * (u_d * ymid + 0.5 * k.l_sd * s))
        return _stack(lam)


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
    bounds = {"fc3_kg": (0.0, math.inf), "fc4_kg": (0.0, math.inf)}  # friction only resists
    # In a lift the rates keep their sign, so the load times their sign is a function of
    # the load, as the saturation is of the hoist current: beside it the residual sees
    # this term only where the rates reverse (docs/diagnosis.md).
    masked_by = ("current_saturation",)
    per_load = True

    def columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((z, z), (z, z))

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [("shipper-shaft friction per tonne of load", "N m/t",
                 lambda v: 1000.0 * v["fc3_kg"]),
                ("saddle-block friction per tonne of load", "N/t",
                 lambda v: 1000.0 * v["fc4_kg"])]

    def payload_columns(self, k: Kinematics) -> np.ndarray:
        z = np.zeros_like(k.d)
        return _stack((smooth_sign(k.thd, SIGN_EPS_TH), z), (z, smooth_sign(k.dd, SIGN_EPS_D)))


@register_term
class CurrentSaturation(ExtensionTerm):
    """Hoist force falls behind the armature current above a knee.

    Armature reaction and the saturating pole tips reduce the flux as the armature
    current grows: the torque curve is straight at low current and flatter above. The
    hoist pull is a linear spline with one knot, F_H = K_H i_H - K_H3 h(i_H - i_k), h a
    hinge (zero below the knee i_k, the current above it) rounded over
    ``KNEE_ROUND_A``: K_H3 / K_H is how much less pull an ampere gives above the knee.
    The knee is a knot at the median of the hoist current in the data, as splines place
    their knots at quantiles: the fit's residual cannot place it (on the bench it chose
    knees near the top of the range, where the held-out payload was worst), and with
    the knot in the middle of the data each half of the curve gets its own slope. On
    the bench's 3 + 3 machines a cubic (the Taylor form of a smooth curve) left twice
    the held-out payload error of the spline, on smooth and on knee-shaped curves
    alike (docs/diagnosis.md). The crowd motor keeps a cubic (``K_C3``, reference
    150 A). Both use the current estimated from the neighbouring samples
    (``Kinematics.i_h_est``, ``i_c_est``): the currents are the outputs, and a column
    built from a sample's own measured current lets the fit predict that sample's noise
    (the crowd cubic once did, and took 2-3 % of the held-out residual on every
    realistic machine).

    The calibration trials (empty, one known load) stay below a full dipper's currents,
    where saturation bites hardest; the diagnosis identifies the term with the verified
    passes too (``needs_full_dipper``).
    """

    name = "current_saturation"
    params = ("K_H3", "K_C3")
    units = ("N per A", "N per A")
    description = "hoist force falling behind the current at high current"
    cause = ("at high current the hoist motors give less pull per ampere "
             "(armature reaction, magnetic saturation)")
    signature = "hoist_current"
    defaults = {"knee_a": 250.0, "crowd_ref_a": 150.0}
    static_params = ("K_H3", "K_C3")
    needs_full_dipper = True
    KNEE_ROUND_A: ClassVar[float] = 20.0

    def for_data(self, tables: list[Any]) -> CurrentSaturation:
        """The knee at the median hoist current of ``tables`` (unless given); the
        default stands where the tables carry no hoist current."""
        if "knee_a" in self.given:
            return self
        self.given.add("knee_a")
        i_h = [np.abs(np.asarray(t.columns["hoist1_a"]) + np.asarray(t.columns["hoist2_a"]))
               for t in tables if {"hoist1_a", "hoist2_a"} <= set(t.columns)]
        i = np.concatenate(i_h) if i_h else np.zeros(0)
        i = i[np.isfinite(i)]
        if len(i):
            self.hyper["knee_a"] = float(np.round(np.median(i)))
        return self

    def columns(self, k: Kinematics) -> np.ndarray:
        u_th, u_d = _unit_hoist(k)
        w = self.KNEE_ROUND_A
        # Kinematics.__post_init__ sets both
        assert k.i_h_est is not None and k.i_c_est is not None
        i = k.i_h_est
        above = np.sign(i) * w * np.logaddexp(0.0, (np.abs(i) - self.h("knee_a")) / w)
        ic3 = k.i_c_est**3 / self.h("crowd_ref_a") ** 2
        return _stack((-above * u_th, -above * u_d), (np.zeros_like(ic3), ic3))

    def shared_columns(self, k: Kinematics) -> dict[str, np.ndarray]:
        """At held poses, the crowd column takes the crowd current's neighbour estimate.

        The measured crowd current sits in the regressor, and its noise (errors in
        variables) shrinks K_C by about 1 %; the cubic, nearly collinear with the linear
        terms, would absorb that as false saturation. While the arm is held still the
        current is steady, so its neighbour estimate is exact and noise-free there. In
        prediction (``i_c_est`` = ``i_c``) the column is unchanged."""
        held = (np.abs(k.thd) < np.radians(0.15)) & (np.abs(k.dd) < 0.004)
        fix = np.where(held, k.i_c - k.i_c_est, 0.0)
        return {"K_C": np.stack([np.zeros_like(fix), fix], axis=-1)}

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {f"hoist pull per ampere lost above the knee at {self.h('knee_a'):g} A":
                values["K_H3"] / values["K_H"]}

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        knee = self.h("knee_a")
        return [(f"hoist pull per ampere above {knee:g} A, short of below it", "%",
                 lambda v: 100.0 * v["K_H3"] / v["K_H"])]


class RopePull:
    """The hoist rope's pull over K_H, for terms whose effect grows with the pull itself
    (a tilted or a sagging boom turns it): not the current as read. The sensors' offset
    comes off it, and at a weakened field an ampere pulls less (``pull``), from the fit's
    own ``i_H0`` and field curve (``search_hyper``). With the current as read, the thesis's
    machine (its lowering strokes at 30 A) gave the slope's kappa 0.61 +- 0.05 for 1 and
    the boom's drop 0.2-0.4 of the simulated one (docs/diagnosis.md, eighteenth and
    nineteenth sessions)."""

    hyper: dict[str, Any]
    given: set[str]

    PULL_KEYS: ClassVar[tuple[str, ...]] = (
        "field_nominal_a", "field_knots_a", "above_top_knot", "below_bottom_knot",
        "spline_ends")
    """The hoist drive's curve settings, copied into ``hyper`` beside ``pull_ratios``."""
    _drive: Any = None
    """The hoist drive's curve built from those settings (``pull``), once."""

    def search_hyper(self, cal: Any, tables: list[Any]) -> None:
        """What the rope's pull needs beside the current (``pull``), from fits of
        ``cal``'s model (this term taking the current as read) on ``tables``: the pull
        per ampere over the field relative to the nominal field's (``pull_ratios``:
        K_H_f<A> / K_H at the hoist drive's knots) and the hoist current sensors' offset
        (``pull_offset_a``: the fit's ``i_H0``). The equation-error form once, with the
        current as read (it has no offsets), then for an output-error calibrator that
        fit once. Data at one field need no ratios. Then the term's own searches."""
        self._search_pull(cal, tables)
        super().search_hyper(cal, tables)  # type: ignore[misc]

    def _search_pull(self, cal: Any, tables: list[Any]) -> None:
        from shoveld.model.terms import HoistDrive

        if "pull_offset_a" in self.given:
            return
        drive = next((t for t in cal.model.terms if isinstance(t, HoistDrive)), None)
        several = drive is not None and len(drive.knots) > 1
        methods = dict.fromkeys(("equation", cal.method) if several else (cal.method,))
        if drive is None or methods.keys() == {"equation"} and not several:
            return
        self.given.add("pull_offset_a")  # the inner fits keep what they are given
        self.hyper["pull_offset_a"] = 0.0
        if several:
            self.hyper.update({key: drive.hyper[key] for key in self.PULL_KEYS
                               if key in drive.hyper})
            self.hyper["pull_ratios"] = [1.0] * len(drive.knots)
        self._drive = None
        for method in methods:
            inner, _, _ = _profile_point(cal, tables, [], method)
            v = inner.params_.as_dict()
            if several:
                self.hyper["pull_ratios"] = [v[name] / v["K_H"] for name in drive.params]
            self.hyper["pull_offset_a"] = v.get("i_H0", 0.0)
            self._drive = None

    def pull(self, k: Kinematics) -> np.ndarray:
        """The rope's pull over K_H: the hoist current less its sensors' offset
        (``pull_offset_a``), times the pull per ampere at each row's field relative to
        the nominal field's (``pull_ratios`` on the hoist drive's curve). Without them,
        the current as measured at the nominal field's pull."""
        assert k.i_h_est is not None  # Kinematics.__post_init__ sets it
        i = k.i_h_est - float(self.hyper.get("pull_offset_a", 0.0))
        ratios = self.hyper.get("pull_ratios")
        if not ratios:
            return i
        if self._drive is None:
            from shoveld.model.terms import HoistDrive

            self._drive = HoistDrive(**{key: self.hyper[key] for key in self.PULL_KEYS
                                        if key in self.hyper})
        return i * (self._drive._basis(k) @ np.asarray(ratios, dtype=float))


@register_term
class GroundSlope(RopePull, ExtensionTerm):
    """The machine stands on a slope; the cab inclinometer sees the tilt.

    The handle angle comes from a gravity-referenced sensor, but the boom angle is
    measured against the machinery deck, so in the arm plane's own frame (its
    horizontal at right angles to gravity's part in the plane) the boom-point sheave
    sits at boom + tilt, the tilt being the deck's lean in that plane: atan2(sin pitch,
    cos slope), the slope's cosine from the inclinometer's pitch and roll (sin^2 slope
    = sin^2 pitch + sin^2 roll). The rope columns change by K_H kappa tilt
    d(rope)/d(boom), kappa = 1 for a true slope (identified, as ``K_H_pitch`` =
    K_H kappa), plus what the tilt does beyond first order, known: the rope's geometry
    at boom + tilt less its first-order part, on K_H's column. Gravity in the arm plane
    is g cos(roll): a known change of the mass columns and of the payload's. The tilt
    turns the rope's pull, which is not the current as read: the sensors' offset comes
    off it, and at a weakened field an ampere pulls less (``pull``, from the fit's own
    ``i_H0`` and field curve, ``search_hyper``).

    The first-order form alone (the tilt taken as the pitch, no curvature) biased kappa
    by +0.05, +0.21 and +0.42 at slopes of 2, 5.5 and 9 degrees on an otherwise ideal
    machine whose hoist field stays nominal when lowering (10 standard errors at 5.5),
    growing with the slope: the curvature it left out (docs/diagnosis.md, sixteenth
    session).
    """

    name = "ground_slope"
    params = ("K_H_pitch",)
    units = ("N per A",)
    description = "machine standing on a slope"
    cause = ("the machine stands on a slope: as it swings, the tilt changes the direction "
             "of gravity against the boom and the arm")
    signature = "pitch"
    static_params = ("K_H_pitch",)
    # kappa = 1 for a true slope; within a factor of two of it. On nine sets of pairs the
    # true slope's fits gave kappa 0.98-1.43 (10th-90th percentile, the first-order form),
    # 510 of 520 in range and 5 standard errors clear of zero; without a slope 0 of 337
    # (median 0.02): the pitch does not vary on level ground (docs/diagnosis.md,
    # fifteenth session). With the rope's curvature (sixteenth): 0.96 +- 0.03.
    predicted = {"K_H_pitch": ("K_H", 0.5, 2.0)}

    @staticmethod
    def tilt(k: Kinematics) -> np.ndarray:
        """The deck's lean in the arm plane (rad) from the inclinometer's pitch and roll."""
        sp, sr = np.sin(k.pitch), np.sin(k.roll)
        return np.arctan2(sp, np.sqrt(np.clip(1.0 - sp * sp - sr * sr, 0.0, None)))

    def columns(self, k: Kinematics) -> np.ndarray:
        g_th, g_d = _unit_hoist_dboom(k)
        q = self.pull(k) * self.tilt(k)
        return _stack((q * g_th, q * g_d))

    def _gravity(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.cos(k.roll) - 1.0, np.cos(k.th), np.sin(k.th)

    def shared_columns(self, k: Kinematics) -> dict[str, np.ndarray]:
        f, c, s = self._gravity(k)
        md = np.stack([f * k.d * G * c, f * G * s], axis=-1)
        mlc = np.stack([-f * G * c, np.zeros_like(c)], axis=-1)
        # The tilt beyond first order, at kappa = 1, on K_H's column, with the pull at the
        # row's field as in the first-order column. The estimated current, so that no
        # column carries the measured current it predicts.
        t = self.tilt(k)
        _, sin_t, cos_t = rope_geometry(k.th, k.d, k.boom + t)
        g_th, g_d = _unit_hoist_dboom(k)
        i = self.pull(k)
        kh = np.stack([i * (-k.d * (sin_t - k.sin_a3) - t * g_th),
                       i * (cos_t - k.cos_a3 - t * g_d)], axis=-1)
        return {"Md": md, "MdLc": mlc, "K_H": kh}

    def payload_phi(self, k: Kinematics) -> np.ndarray:
        f, c, s = self._gravity(k)
        return np.stack([f * k.d * G * c, f * G * s], axis=-1)

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"kappa (1 for a true slope)": values["K_H_pitch"] / values["K_H"]}

    KAPPA: ClassVar[str] = "boom tilt per degree of deck pitch (1 for a machine on a slope)"
    # No model error: with the rope's pull taken less the sensors' offset and at the
    # field (``pull``), kappa is +0.004 +- 0.012 off on 20 realistic machines and +0.003
    # +- 0.013 on 20 others, the fit's own std holding it (RMS of error over std 0.82 and
    # 0.85; bench/findings_coverage.py, seed offsets 5000 and 9000). With the current as
    # read it was -0.038 +- 0.037 and -0.058 +- 0.033, and a model error of 0.05 stood in
    # for the cause (docs/diagnosis.md, seventeenth and eighteenth sessions).
    model_error: ClassVar[dict[str, float]] = {}

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [(self.KAPPA, "", lambda v: v["K_H_pitch"] / v["K_H"])]


@register_term
class BoomSuspensionSpring(RopePull, ExtensionTerm):
    """The boom angle moves with the rope load (suspension ropes and boom stretch).

    The boom point drops in proportion to the moment of the rope's pull about the boom
    foot. The pull is K_H p, p the pull over K_H (``RopePull.pull``: the hoist current
    less its sensors' offset, at the pull per ampere of the row's field); its moment
    per newton is the bail rope's, which follows the pose (``_bail_share``, r = 1 at
    the reference pose: the handle at ``ref_th_deg``, the bail ``ref_d_m`` out):
    boom_true = boom - sag r p / I_ref. The drum rope runs back along the boom, its arm
    about the foot small and fixed: its part is taken with the bail's. To first order
    the rope columns change by -K_H sag (r p^2 / I_ref) d(rope)/d(boom); the parameter
    is K_H_sag = K_H sag, and sag (rad at the reference current I_ref at the nominal
    field, at the reference pose) follows. With the current as read in place of p, the
    thesis's machine (its lowering strokes at a 30 A field) gave 0.58 deg for a
    simulated 2.45; with the pull and one drop per newton at every pose, 0.84 +- 0.09
    of the truth on drawn machines (docs/diagnosis.md, nineteenth and twentieth
    sessions).
    """

    name = "boom_suspension_spring"
    params = ("K_H_sag",)
    units = ("N per A",)
    description = "boom point dropping under rope load"
    cause = ("the boom suspension ropes stretch under the hoist pull, so the boom point "
             "(and the rope angle) moves with the load")
    signature = "hoist_current"
    defaults = {"ref_a": 500.0, "ref_th_deg": 0.0, "ref_d_m": 8.5, "moment": "bail"}
    static_params = ("K_H_sag",)
    bounds = {"K_H_sag": (0.0, math.inf)}  # the boom point drops under the pull, never rises

    def __init__(self, **hyper: Any) -> None:
        super().__init__(**hyper)
        if self.hyper["moment"] not in ("bail", "none"):
            raise ValueError(f"hyper.{self.name}.moment: expected 'bail' or 'none', got "
                             f"{self.hyper['moment']!r}")
        if not 0.0 < self.h("ref_d_m") <= 12.0 or not -60.0 <= self.h("ref_th_deg") <= 30.0:
            raise ValueError(f"hyper.{self.name}: expected the reference pose's ref_d_m in "
                             "(0, 12] m and ref_th_deg in [-60, 30] deg (below the boom), got "
                             f"{self.h('ref_d_m'):g} m and {self.h('ref_th_deg'):g} deg")

    @classmethod
    def file_hyper(cls, hyper: dict[str, Any]) -> dict[str, Any]:
        """A params file without ``moment`` was identified with one drop per newton at
        every pose (before the twentieth session): "none" keeps that form."""
        return hyper if "moment" in hyper else {**hyper, "moment": "none"}

    def _bail_share(self, k: Kinematics) -> np.ndarray:
        """The bail rope's moment per newton about the boom foot at each row over the
        reference pose's, both at the row's boom angle. It is d sin(boom - th) / l_SD
        times the foot-to-sheave length (the foot lies on the boom line), and by the
        law of sines d sin(boom - th) / l_SD = d sin(a3) / L_BS: the ratio is that of
        the rope's handle torques per newton, d sin(a3) (``rope_geometry``)."""
        d0 = self.h("ref_d_m")
        _, sin_ref, _ = rope_geometry(np.full_like(k.boom, math.radians(self.h("ref_th_deg"))),
                                      np.full_like(k.boom, d0), k.boom)
        return (k.d * k.sin_a3) / (d0 * sin_ref)

    def columns(self, k: Kinematics) -> np.ndarray:
        g_th, g_d = _unit_hoist_dboom(k)
        p = self.pull(k)
        q = -p * p / self.h("ref_a")
        if self.hyper["moment"] == "bail":
            q = q * self._bail_share(k)
        return _stack((q * g_th, q * g_d))

    def derived(self, values: dict[str, float]) -> dict[str, float]:
        return {"boom drop at the reference current and pose, deg":
                math.degrees(values["K_H_sag"] / values["K_H"])}

    def _drop(self) -> str:
        """The value's wording: at the reference current and pose, or, in the form of one
        drop per newton, at no pose."""
        a = self.h("ref_a")
        if self.hyper["moment"] == "none":
            return f"boom point drop at {a:g} A of hoist current"
        return (f"boom point drop at {a:g} A of hoist current, the bail "
                f"{self.h('ref_d_m'):g} m out at {self.h('ref_th_deg'):g} deg")

    # With one drop per newton at every pose the value was the pose-averaged one, 0.84 +-
    # 0.09 of the reference pose's on 20 realistic machines (model error 0.36 deg). With
    # the bail rope's moment (``_bail_share``): 1.03 +- 0.06, the RMS of error over the
    # fit's own std 1.15, one with 0.056 deg at 500 A; on 20 others 0.80 with the fit's
    # std alone (bench/findings_coverage.py, seed offsets 5000 and 9000; twentieth
    # session). What is left grows with the drop (+1 % at 1 deg per MN, +4 % at 3): the
    # columns are first-order in the sag. Scaled with the reference current, the same at
    # any reference pose (``error_of``).
    model_error: ClassVar[dict[str, float]] = {
        "boom point drop at 500 A of hoist current, the bail 8.5 m out at 0 deg": 0.056}
    flat_model_error: ClassVar[float] = 0.36
    """The drop's model error at 500 A in the form of one drop per newton at every pose
    (``moment = "none"``: params files written before the twentieth session)."""

    def quantities(self) -> list[tuple[str, str, Callable[[dict[str, float]], float]]]:
        return [(self._drop(), "deg", lambda v: math.degrees(v["K_H_sag"] / v["K_H"]))]

    def error_of(self, what: str) -> float:
        """The drop's model error at the term's reference current (it grows with it)."""
        if what == self._drop():
            (bail,) = self.model_error.values()
            flat = self.hyper["moment"] == "none"
            return (self.flat_model_error if flat else bail) * self.h("ref_a") / 500.0
        return super().error_of(what)


EFFECT_TERMS: tuple[str, ...] = (
    "swing_centrifugal", "sensor_time_skew", "payload_cog_offset",
    "hoist_rope_mass", "load_dependent_friction", "current_saturation", "ground_slope",
    "boom_suspension_spring")
"""The candidate library of the diagnosis, in a fixed order. ``hoist_field_weakening``
is no longer in it: the base model's hoist drive carries K_H over the field current
(``shoveld.model.terms.HoistDrive``), so a drive that forces or weakens its field is
modelled, not diagnosed."""
