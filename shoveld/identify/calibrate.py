"""Identification of the model parameters (``shoveld calibrate``).

Empty and known-load trials are stacked; the known load fixes the scale (the
equations are otherwise homogeneous). ``method="output"`` (the default) fits the
measured hoist and crowd currents as the outputs, weighted by their noise, with
the current sensors' offsets and the hoist's pull per ampere over the field
current (``shoveld.identify.output_error``). ``method="equation"`` is the thesis's
form with the currents inside the regressor (normalised by K_H), kept as the
starting point and for comparison: its errors in variables bias K_H and K_C low.
Samples where the model does not hold are excluded with a reason, and the report
says how many and why.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from shoveld.identify import ANGLE_DRIFT_DEG, output_error
from shoveld.identify.output_error import fit_output
from shoveld.kinematics import (
    DEFAULT_POLYORDER,
    DEFAULT_WINDOW_S,
    PAYLOAD_POLYORDER,
    PAYLOAD_WINDOW_S,
    window_samples,
)
from shoveld.kinematics.offline import difference_noise, offline_kinematics
from shoveld.model.kin import Kinematics
from shoveld.model.model import EQUATIONS, Model
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable
from shoveld.words import n_of

METHODS = ("output", "equation")


@dataclass(frozen=True)
class ExclusionConfig:
    """When a sample is not used for identification."""

    current_full_scale_a: float = 4000.0
    saturation_fraction: float = 0.98
    hoist_field_nominal_a: float = 70.0
    weak_field_fraction: float = 0.97
    min_rope_current_a: float = 20.0
    static_rate_deg_s: float = 0.15
    static_crowd_m_s: float = 0.004
    static_acc_deg_s2: float = 1.0
    friction_min_rate_deg_s: float = 1.0
    friction_min_crowd_m_s: float = 0.02


@dataclass
class FileData:
    """One table prepared for fitting: kinematics, known payload, used-sample mask."""

    name: str
    kin: Kinematics
    payload: np.ndarray
    use: np.ndarray
    static: np.ndarray
    excluded: Counter[str]
    noise: dict[str, float] = field(default_factory=dict)
    """White noise (1 sigma) of the position readings the kinematics are smoothed from,
    from their third differences: ``th`` (rad) and ``d`` (m)."""


NEIGHBOUR_CURRENTS_S = 0.5
"""Span of the neighbouring samples that estimate a current for terms nonlinear in it."""


def exclusion_masks(table: SignalsTable, model: Model, cfg: ExclusionConfig,
                    window_s: float = DEFAULT_WINDOW_S,
                    polyorder: int = DEFAULT_POLYORDER) -> FileData:
    """Kinematics of a table and, per sample, whether and why it is excluded."""
    cols = model.transform(dict(table.columns))
    kin, ok = offline_kinematics(cols, window_s, polyorder)
    # Terms nonlinear in a current take it from the neighbouring samples (see Kinematics),
    # over a fixed half second: what the extension terms were measured with, whatever the
    # smoothing of the angles.
    kin.estimate_currents(int(round(NEIGHBOUR_CURRENTS_S * table.sample_rate_hz)))
    n = len(kin)
    reasons = np.full(n, "", dtype=object)
    payload = table.payload_truth()

    def mark(mask: np.ndarray, why: str) -> None:
        reasons[(reasons == "") & mask] = why

    mark(~ok, "missing or invalid samples (and the smoothing window around them)")
    full = cfg.current_full_scale_a * cfg.saturation_fraction
    sat = np.zeros(n, dtype=bool)
    for c in ("hoist1_a", "hoist2_a", "crowd_a"):
        sat |= np.abs(np.nan_to_num(cols[c])) >= full
    mark(sat, "saturated current sensor")
    mark(~np.isfinite(payload), "payload unknown")
    if not any(getattr(t, "uses_field_current", False) for t in model.terms):
        weak = np.nan_to_num(kin.i_hf) < cfg.weak_field_fraction * cfg.hoist_field_nominal_a
        mark(weak, "lowering with the weak hoist field (K_H identified at the hoisting field)")
    mark(np.nan_to_num(kin.i_h) < cfg.min_rope_current_a, "hoist rope slack")
    from shoveld.cycle.offline import label_phases
    from shoveld.cycle.phases import DIG, DUMP

    if not fixed_load_trial(table):
        # A trial with one known load all through (a calibration trial: held poses and
        # free motion in the air) has no bank and no dump; the phase machine would take
        # its rising strokes for digging.
        phases = label_phases(kin)
        mark(phases == DIG, "digging (bank forces are not in the model)")
        mark(phases == DUMP, "dumping (payload leaving the dipper)")
    use = reasons == ""
    static = use & (np.abs(np.degrees(np.nan_to_num(kin.thd))) < cfg.static_rate_deg_s) & (
        np.abs(np.nan_to_num(kin.dd)) < cfg.static_crowd_m_s) & (
        np.abs(np.degrees(np.nan_to_num(kin.thdd))) < cfg.static_acc_deg_s2)
    # A held pose is still: its rates and accelerations are zero, not the noise the fit
    # differentiated. Left in, that noise made the Coulomb columns tanh(noise) (up to
    # +-0.7 on the crowd) where the machine has no friction to show, and pulled the
    # Coulomb terms 4-6 % low and the viscous ones as much high (docs/engine.md).
    for name in ("thd", "thdd", "dd", "ddd"):
        getattr(kin, name)[static] = 0.0
    excluded = Counter(str(r) for r in reasons[~use])
    noise = {"th": difference_noise(np.radians(cols["handle_deg"]), 3),
             "d": difference_noise(cols["crowd_m"], 3)}
    return FileData(table.source, kin, payload, use, static, excluded, noise)


NOISE_STRIDE = 4
"""The position noise's correction is taken on every 4th sample: on 3 machines the
parameters moved by under 0.004 standard errors against every sample, and calibration
took 0.65-0.74 s instead of 1.02-1.18 s (0.70 s without the correction)."""
POSITION_SENSORS = {"th": ("thd", "thdd"), "d": ("dd", "ddd")}
"""The position readings whose noise the fit corrects for, and the rate and
acceleration smoothed from each."""


def position_noise_errors(files: list[FileData], window_s: float, polyorder: int
                          ) -> list[output_error.InputError]:
    """The handle angle's and the crowd extension's noise as errors in the rates and
    accelerations of the used samples (files concatenated as the fit takes them).

    On held poses the rates and accelerations are set to zero, not smoothed from the
    readings, so there they carry no error."""
    dt = float(np.median(np.concatenate([np.diff(f.kin.t) for f in files])))
    window = window_samples(window_s, dt, polyorder)
    moving = np.concatenate([~f.static[f.use] for f in files]).astype(float)
    errors = []
    for key, names in POSITION_SENSORS.items():
        sigma = float(np.median([f.noise.get(key, 0.0) for f in files]))
        if sigma > 0:
            errors += [replace(e, shift={n: moving for n in e.shift}, stride=NOISE_STRIDE)
                       for e in output_error.rate_errors(sigma, names, dt, window, polyorder)]
    return errors


def fixed_load_trial(table: SignalsTable) -> bool:
    """Does the table carry one known load all through (a calibration trial)?"""
    if "known_payload_kg" in table.meta:
        return True
    pay = table.payload_truth()
    return bool(len(pay) and np.all(np.isfinite(pay)) and np.ptp(pay) == 0.0)


def integrated_autocorrelation(r: np.ndarray, max_lag: int = 200) -> float:
    """1 + 2 sum of the residual autocorrelation (until it falls below 0.05).

    Samples at 50 Hz are not independent; ordinary least-squares standard errors
    would be too small by about the square root of this factor. (The autocorrelation
    by FFT: the same numbers as the lag-by-lag dot products, in one pass.)
    """
    r = r - r.mean()
    n = len(r)
    var = float(r @ r)
    if var <= 0 or n < 10:
        return 1.0
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(r, size)
    acf = np.fft.irfft(f * np.conj(f), size)[:min(max_lag, n // 4)] / var
    tau = 1.0
    for rho in acf[1:]:
        if rho < 0.05:
            break
        tau += 2.0 * float(rho)
    return tau


@dataclass
class StageResult:
    name: str
    params: list[str]
    samples: int
    condition_number: float
    residual_rms: dict[str, float]


def _solve(a: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares with column scaling; returns p and (A^T A)^-1."""
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    an = a / scale
    # normal equations of the column-scaled problem (condition ~50, so its square is
    # harmless in float64): a P x P solve instead of an N x P factorisation
    inv = np.linalg.pinv(an.T @ an)
    p_n = inv @ (an.T @ y)
    return p_n / scale, inv / np.outer(scale, scale)


def condition_number(a: np.ndarray) -> float:
    """Of the column-normalised regressor: how well the data separate the parameters."""
    norms = np.linalg.norm(a, axis=0)
    sv = np.linalg.svd(a / np.where(norms > 0, norms, 1.0), compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf


REFERENCE_PARAM = "K_H"
"""The equations are divided by this parameter before fitting (see ``_solve_normalized``)."""


def _solve_normalized(wn: np.ndarray, yn: np.ndarray, ref: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit with the reference column moved to the right-hand side.

    The equations are homogeneous and the hoist current is measured with noise.
    Left in the regressor, that noise acts like a ridge penalty on the whole
    parameter vector and shrinks it (about 5 % on simulated trials). Divided by
    K_H, the noisy current becomes the response and the known payload term fixes
    the scale: theta = (p_j / K_H, 1 / K_H). p and its covariance follow by the
    delta method.
    """
    n_eq = yn.shape[1]
    w_ref = wn[:, :, ref]
    others = [j for j in range(wn.shape[2]) if j != ref]
    a = np.concatenate([wn[:, :, others], -yn[:, :, None]], axis=2).reshape(-1, len(others) + 1)
    b = -w_ref.reshape(-1)
    theta, inv = _solve(a, b)
    r_theta = (a @ theta - b).reshape(-1, n_eq)
    s2 = float(np.sum(r_theta**2)) / max(1, a.shape[0] - len(theta))
    tau = max(integrated_autocorrelation(r_theta[:, 0]), integrated_autocorrelation(r_theta[:, 1]))
    cov_t = inv * s2 * tau
    k_ref = 1.0 / theta[-1]
    p = np.empty(wn.shape[2])
    p[others] = theta[:-1] * k_ref
    p[ref] = k_ref
    jac = np.zeros((len(p), len(theta)))
    for i, j in enumerate(others):
        jac[j, i] = k_ref
        jac[j, -1] = -theta[i] * k_ref**2
    jac[ref, -1] = -(k_ref**2)
    cov = jac @ cov_t @ jac.T
    r = r_theta * k_ref
    return p, cov, r


@dataclass
class Calibrator:
    """Identify the parameters of ``model`` from calibration trials (fit/predict style)."""

    model: Model = field(default_factory=Model.from_names)
    method: str = "output"
    exclusion: ExclusionConfig = field(default_factory=ExclusionConfig)
    window_s: float = DEFAULT_WINDOW_S
    """Zero-phase smoothing of the joint angles for identification (recorded in the
    params; the engine's payload equations use ``payload_window_s``)."""
    polyorder: int = DEFAULT_POLYORDER
    payload_window_s: float = PAYLOAD_WINDOW_S
    """The payload equations' own smoothing, recorded for the engine: lift and swing are
    slower than the trials' strokes, and a longer fit there is less noisy."""
    payload_polyorder: int = PAYLOAD_POLYORDER
    angle_drift_deg: float = ANGLE_DRIFT_DEG
    """The handle-angle sensor's slow drift within a file (1 sigma), counted in the
    standard errors; 0 leaves it out."""
    position_noise: bool = True
    """Correct the fit for the handle angle's and the crowd extension's noise (errors in
    variables, :func:`position_noise_errors`). On by default since 2026-11-26 (sixth
    session), with the 7th-order smoothing over 1.0 s (``shoveld.kinematics``): left
    in, the noise biased K_C by +0.51 standard errors over 120 simulated machines
    (docs/engine.md, "The smoothing's bias on the fast strokes"). False: the fit as
    before, for comparison."""
    files_: list[FileData] = field(default_factory=list, init=False)
    params_: ModelParams | None = field(default=None, init=False)
    output_fit_: output_error.OutputFit | None = field(default=None, init=False)
    """The output-error fit behind ``params_`` (its angle sensitivities, noise model)."""
    stages_: list[StageResult] = field(default_factory=list, init=False)
    row_residuals_: np.ndarray | None = field(default=None, init=False)
    """(N, 2): the fit's residual per used sample (the rows of ``files_`` with ``use``, in
    order): the equation-error form's in the equations' units, the output-error form's
    in amps (NaN where a channel is not used); what a search over a hyper-parameter sums
    block by block (``shoveld.model.effects``)."""

    def prepare(self, tables: list[SignalsTable]) -> list[FileData]:
        return [exclusion_masks(t, self.model, self.exclusion, self.window_s, self.polyorder)
                for t in tables]

    def _rows(self, files: list[FileData]) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Stacked (W + m Psi), y = -m phi of the used samples, and per file the per-row
        mask of equations that carry information."""
        ws, ys, oks = [], [], []
        ex = self.exclusion
        for f in files:
            mask = f.use
            if not mask.any():
                continue
            k = f.kin.take(mask)
            w, phi, psi = self.model.regressor(k)
            m = f.payload[mask][:, None, None]
            # Near standstill the sign of a noisy rate is a coin toss: Coulomb friction is
            # undetermined there, so those equation rows carry no information (held poses
            # excepted: there the friction is whatever holds them, and the rows keep
            # gravity).
            slow = np.stack([np.abs(k.thd) < np.radians(ex.friction_min_rate_deg_s),
                             np.abs(k.dd) < ex.friction_min_crowd_m_s], axis=1)
            slow &= ~f.static[mask][:, None]
            ws.append(np.where(slow[:, :, None], 0.0, w + m * psi))
            ys.append(np.where(slow, 0.0, -m[:, :, 0] * phi))
            oks.append(~slow)
        n_p = len(self.model.param_names)
        if not ws:
            return np.zeros((0, 2, n_p)), np.zeros((0, 2)), []
        return np.concatenate(ws), np.concatenate(ys), oks

    def fit(self, tables: list[SignalsTable]) -> Calibrator:
        method = {"joint": "equation", "staged": "equation"}.get(self.method, self.method)
        if method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}; use one of {', '.join(METHODS)}")
        # Hyper-parameters the data choose (knots where the data lie), then those found
        # by fits (shoveld.model.effects).
        terms = [t.for_data(tables) for t in self.model.terms]
        if any(a is not b for a, b in zip(terms, self.model.terms, strict=True)):
            self.model = Model(terms)
        for t in self.model.terms:
            # A term with a nonlinear constant (a delay, a radius, the rope's pull)
            # finds it first by fits of this same calibrator (shoveld.model.effects).
            search = getattr(t, "search_hyper", None)
            if search is not None:
                search(self, tables)
        self.files_ = self.prepare(tables)
        names = self.model.param_names
        w_all, y_all, oks = self._rows(self.files_)
        if len(w_all) < 10:
            raise ValueError("fewer than 10 usable samples after exclusions: "
                             + "; ".join(f"{f.name}: {dict(f.excluded)}" for f in self.files_))
        known = [f.payload[f.use] for f in self.files_]
        loads = np.unique(np.round(np.concatenate(known)))
        if not np.any(loads > 0):
            raise ValueError("no sample with a known non-zero payload: the equations are "
                             "homogeneous, a known-load trial is needed to fix the scale")
        p, cov, sigma = self._fit_equation(w_all, y_all)
        fit: dict[str, Any] = {"method": method, "samples": int(len(w_all)),
                               "window_s": self.window_s, "polyorder": self.polyorder,
                               "payload_window_s": self.payload_window_s,
                               "payload_polyorder": self.payload_polyorder}
        current_noise: dict[str, dict[str, float]] = {}
        if method == "output":
            files = [f for f in self.files_ if f.use.any()]
            of = fit_output(self.model, [f.kin.take(f.use) for f in files],
                            [f.payload[f.use] for f in files],
                            [np.asarray(o) for o in oks], p,
                            angle_drift_deg=self.angle_drift_deg,
                            field_noise=float(np.median([output_error.field_noise_a(
                                f.kin.i_hf) for f in files])),
                            input_errors=position_noise_errors(
                                files, self.window_s, self.polyorder)
                            if self.position_noise else ())
            self.output_fit_ = of
            self.row_residuals_ = of.row_residuals
            p, cov = of.p, of.cov
            sigma = np.array([of.force_rms["handle"], of.force_rms["crowd"]])
            current_noise = of.noise
            fit.update(condition_number=of.condition_number,
                       residual_rms={eq: float(s) for eq, s in zip(EQUATIONS, sigma,
                                                                    strict=True)},
                       current_residual_rms_a=of.residual_rms, iterations=of.iterations,
                       covariance=f"sandwich over {n_of(of.blocks, 'block', 'blocks')} of "
                                  f"{output_error.BLOCK_S:g} s, plus a handle-angle drift "
                                  f"of {self.angle_drift_deg:g} deg per file",
                       angle_drift_deg=self.angle_drift_deg)
            fit["input_noise_corrected"] = of.corrected
            if self.position_noise:
                # What the errors-in-variables correction took each reading's noise to be.
                fit["position_noise"] = {
                    "handle_deg": math.degrees(float(np.median([f.noise["th"] for f in files]))),
                    "crowd_m": float(np.median([f.noise["d"] for f in files]))}
        else:
            cond = condition_number((w_all / sigma[None, :, None]).reshape(-1, len(names)))
            fit.update(condition_number=cond,
                       residual_rms={eq: float(s) for eq, s in zip(EQUATIONS, sigma,
                                                                    strict=True)})
        hyper = {t.name: dict(t.hyper) for t in self.model.terms if t.hyper}
        excluded: dict[str, Any] = {}
        for f in self.files_:
            excluded[f.name] = {"used": int(f.use.sum()), "static": int(f.static.sum()),
                                **{k: int(v) for k, v in f.excluded.items()}}
        fit["excluded"] = excluded
        self.params_ = ModelParams(
            terms=self.model.term_names, names=names, values=p,
            stderr=np.sqrt(np.clip(np.diag(cov), 0, None)), cov=cov,
            noise={eq: float(s) for eq, s in zip(EQUATIONS, sigma, strict=True)},
            hyper=hyper, fit=fit, current_noise=current_noise)
        return self

    def _fit_equation(self, w_all: np.ndarray, y_all: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The thesis's equation-error form, normalised by K_H, reweighted once by each
        equation's residual RMS. The current sensors' offsets are not in this form (they
        stay 0)."""
        names = self.model.param_names
        idx = list(range(len(names)))
        off = self.model.offset_index
        if off is not None:
            idx = [i for i in idx if i not in off]
        sigma = np.array([1e5, 1e4])
        p = np.zeros(len(names))
        cov = np.zeros((len(names), len(names)))
        for _ in range(2):  # second pass reweights with the first pass's residual RMS
            self.stages_ = []
            p_i, cov_i = self._stage("equation", w_all, y_all, idx, sigma)
            p[idx] = p_i
            cov[np.ix_(idx, idx)] = cov_i
            res = (w_all @ p) - y_all
            sigma = np.sqrt(np.mean(res**2, axis=0))
        self.row_residuals_ = res
        return p, cov, sigma

    def _stage(self, name: str, w: np.ndarray, y: np.ndarray, idx: list[int],
               sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        names = self.model.param_names
        wn = w[:, :, idx] / sigma[None, :, None]
        yn = y / sigma[None, :]
        ref = names.index(REFERENCE_PARAM) if REFERENCE_PARAM in names else -1
        if ref in idx:
            p, cov, r = _solve_normalized(wn, yn, idx.index(ref))
        else:
            a = wn.reshape(-1, len(idx))
            b = yn.reshape(-1)
            p, inv = _solve(a, b)
            r = (a @ p - b).reshape(-1, 2)
            s2 = float(np.sum(r**2)) / max(1, a.shape[0] - len(idx))
            tau = max(integrated_autocorrelation(r[:, 0]), integrated_autocorrelation(r[:, 1]))
            cov = inv * s2 * tau
        cond = (condition_number(wn.reshape(-1, len(idx))) if self.method == "equation"
                else math.nan)  # a starting point for the output-error fit: not reported
        rms = np.sqrt(np.mean(r**2, axis=0)) * sigma
        self.stages_.append(StageResult(name, [self.model.param_names[i] for i in idx],
                                        int(w.shape[0]), cond,
                                        {eq: float(v) for eq, v in zip(EQUATIONS, rms,
                                                                        strict=True)}))
        return p, cov
