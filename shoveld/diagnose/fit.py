"""Identify a model (the project's Calibrator) and judge it on passes it was not fitted on.

A model whose terms the calibration trials excite is identified on the trials
alone; every measured pass is then held out. A term only swinging excites
(``swing_centrifugal``, when the trials do not swing) needs operating data: the
model is then identified on the trials plus the verified passes of all but one
fold, and judged on that fold, round the folds (cross-validation over passes).
Either way each pass is judged by a model that has not seen it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from shoveld.diagnose.data import VERIFIED_SUFFIX, DataSet, Pass
from shoveld.identify.calibrate import Calibrator, FileData
from shoveld.kinematics import (
    DEFAULT_POLYORDER,
    DEFAULT_WINDOW_S,
)
from shoveld.model.kin import Kinematics
from shoveld.model.model import EQUATIONS, Model
from shoveld.model.output import CHANNELS, CurrentEquations, noise_sigma
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable

N_FOLDS = 3
SWING_EXCITED_RAD_S = 0.1
SWING_EXCITED_S = 5.0
"""Calibration trials that swing faster than ``SWING_EXCITED_RAD_S`` for this long (a
swing to a truck and back) excite the swing terms; otherwise the verified passes are
needed."""


class DiagCalibrator(Calibrator):
    """The project's ``Calibrator``, fed the diagnosis's prepared data for a fold (with
    the calibration's defaults, the angles' noise corrected: left in, with the 1.0 s
    smoothing, the boom spring of ``tests/diagnose/test_detect.py`` went unnamed)."""

    def __init__(self, model: Model, dataset: DataSet, train: set[int] | None,
                 **options: Any) -> None:
        """``options``: any other of ``Calibrator``'s settings (method, drift, the
        angles' noise, the payload's smoothing), passed through as they are, so a new
        setting needs no change here; the exclusion and the identification's smoothing
        are the dataset's, which cut the passes with them."""
        super().__init__(model=model, exclusion=dataset.exclusion,
                         window_s=dataset.window_s, polyorder=dataset.polyorder, **options)
        self.dataset = dataset
        self.train = train

    def prepare(self, tables: list[SignalsTable]) -> list[FileData]:
        return self.dataset.training_files(self.model, self.train)


def passes_to_trials_rms(cal: Calibrator) -> dict[str, float]:
    """Per channel, the RMS of the verified passes' residuals over the trials' in ``cal``,
    a calibration with both (``calibrate_with_verified``); empty without either."""
    files = [f for f in cal.files_ if f.use.any()]
    res = cal.row_residuals_
    if res is None:
        return {}
    parts: dict[bool, list[np.ndarray]] = {True: [], False: []}
    k = 0
    for f in files:
        n = int(np.count_nonzero(f.use))
        parts[f.name.endswith(VERIFIED_SUFFIX)].append(res[k:k + n])
        k += n
    if k != len(res) or not parts[True] or not parts[False]:
        return {}
    with np.errstate(invalid="ignore"):
        rms = {v: np.sqrt(np.nanmean(np.concatenate(parts[v]) ** 2, axis=0)) for v in parts}
    names = CHANNELS if cal.method == "output" else EQUATIONS
    return {ch: round(float(rms[True][j] / rms[False][j]), 3)
            for j, ch in enumerate(names) if rms[False][j] > 0}


def calibrate_with_verified(model: Model, trials: list[SignalsTable],
                            verified: list[SignalsTable],
                            window_s: float = DEFAULT_WINDOW_S,
                            polyorder: int = DEFAULT_POLYORDER, **options: Any
                            ) -> tuple[Calibrator, int, int]:
    """Identify ``model`` on the trials plus every scale-verified pass of the ``verified``
    tables (``shoveld calibrate --verified``): the passes bring a full dipper's currents,
    which the trials lack. ``options``: ``Calibrator``'s other settings. Returns the
    fitted calibrator, the verified passes used and the passes found; none verified
    raises ValueError."""
    ds = DataSet(trials, verified, window_s=window_s, polyorder=polyorder)
    train = {p.index for p in ds.passes if p.verified}
    if not train:
        raise ValueError("no pass with a verified payload (the payload_kg column must hold "
                         "the weighed payload through each verified pass)")
    cal = DiagCalibrator(model, ds, train, **options).fit(ds.calib)
    ratio = passes_to_trials_rms(cal)
    if ratio and cal.params_ is not None:
        cal.params_.fit["passes_to_trials_rms"] = ratio  # recorded with the fitted model
    return cal, len(train), len(ds.passes)


def unexcited_by_trials(model: Model, trials: list[SignalsTable],
                        window_s: float = DEFAULT_WINDOW_S,
                        polyorder: int = DEFAULT_POLYORDER) -> list[str]:
    """The model's terms the calibration trials alone cannot identify, each with why (the
    diagnosis identifies them with the verified passes; ``shoveld calibrate`` asks for
    them): a swing term on trials that do not swing takes whatever values the fit leaves
    it, and weighed the passes of a swinging machine 8 t heavy (``bench/pass_misfit.py
    --effects --extend``). A term of a full dipper's currents (``needs_full_dipper``) is
    not refused: on the trials alone the saturation's still helps (the passes' RMS 304 ->
    122 kg, the same bench); docs/diagnosis.md advises a trial near a full dipper's load."""
    out = []
    swing_s: float | None = None
    for t in model.terms:
        if getattr(t, "needs_swing", False):
            if swing_s is None:
                swing_s = DataSet(trials, [], window_s=window_s,
                                  polyorder=polyorder).calib_swing_s(SWING_EXCITED_RAD_S)
            if swing_s < SWING_EXCITED_S:
                out.append(f"{t.name}: only swinging excites it, and the trials swing faster "
                           f"than {SWING_EXCITED_RAD_S:g} rad/s for {swing_s:.1f} s (at least "
                           f"{SWING_EXCITED_S:g} s needed)")
    return out


def needs_operation(model: Model, dataset: DataSet) -> bool:
    """Does the model have a term the calibration trials cannot identify?"""
    if any(getattr(t, "needs_full_dipper", False) for t in model.terms):
        return True
    if not any(getattr(t, "needs_swing", False) for t in model.terms):
        return False
    return dataset.calib_swing_s(SWING_EXCITED_RAD_S) < SWING_EXCITED_S


def fit(dataset: DataSet, effects: list[str], hyper: dict[str, dict[str, Any]],
        train: set[int] | None, method: str = "output") -> ModelParams:
    """Identify base + ``effects`` on the trials (plus the passes in ``train``)."""
    model = Model.from_names(effects, {k: dict(v) for k, v in hyper.items()})
    cal = DiagCalibrator(model, dataset, train, method=method).fit(dataset.calib)
    assert cal.params_ is not None
    return cal.params_


@dataclass
class PassScore:
    """How one model did on one held-out pass."""

    loss: float
    """Mean over the pass's samples of the squared current residuals (hoist and crowd,
    each in units of ``sigma0``), with the payload known (verified) or fitted."""
    payload_kg: float
    """The model's estimate from the pass's lift and swing (offline, least squares)."""
    samples: int
    calib_std_kg: float = 0.0
    """Payload std that the calibration's parameter uncertainty alone causes."""


@dataclass
class Evaluation:
    """A model judged pass by pass on data it was not fitted on."""

    effects: list[str]
    folds: list[ModelParams]
    fold_of: dict[int, int]
    scores: dict[int, PassScore]
    cross_validated: bool
    final: ModelParams | None = None
    """Fitted on everything it may use (the trials, and all verified passes if needed)."""
    extra: dict[str, Any] = field(default_factory=dict)

    def loss(self, passes: list[Pass]) -> np.ndarray:
        return np.array([self.scores[p.index].loss for p in passes])

    def payload_errors(self, passes: list[Pass]) -> np.ndarray:
        return np.array([self.scores[p.index].payload_kg - p.payload_kg for p in passes
                         if p.verified])

    def hyper(self) -> dict[str, dict[str, Any]]:
        p = self.final or self.folds[0]
        return {k: dict(v) for k, v in p.hyper.items()}


def assign_folds(passes: list[Pass], k: int) -> dict[int, int]:
    """Verified passes round-robin over k folds, the others likewise."""
    out: dict[int, int] = {}
    ver = [p for p in passes if p.verified]
    oth = [p for p in passes if not p.verified]
    for i, p in enumerate(ver):
        out[p.index] = i % k
    for i, p in enumerate(oth):
        out[p.index] = i % k
    return out


def as_measured(k: Kinematics) -> Kinematics:
    """The kinematics with the currents as measured in every term.

    Identification gives terms nonlinear in a current its neighbour estimate, so that
    its noise does not correlate with the other side of the equation; a prediction,
    like the live engine, uses the measured current throughout."""
    return replace(k, i_h_est=k.i_h, i_c_est=k.i_c)


def current_residuals(model: Model, k: Kinematics, p: np.ndarray, m: float | np.ndarray
                      ) -> np.ndarray:
    """(N, 2): measured minus predicted hoist and crowd current, A (``k`` should come
    from ``as_measured``)."""
    return CurrentEquations(model, k).residual(p, m)


def score_pass(params: ModelParams, dataset: DataSet, p: Pass, sigma0: np.ndarray,
               valid_ref: list[np.ndarray]) -> PassScore:
    """Residual loss and payload estimate of one pass under ``params``.

    Both in current units (``shoveld.model.output``): measured minus predicted hoist and
    crowd current, which every model predicts whatever its parameters mean. The payload
    is the noise-weighted least squares of the model's own noise model (as the engine
    weighs it); the loss is in the common unit ``sigma0`` (A per channel), so models
    with different noise models compare on the same scale.
    """
    model = params.model()
    view = dataset.view(model)
    f = view.measured[p.table]
    idx = p.eval_idx[valid_ref[p.table][p.eval_idx] & f.use[p.eval_idx]]
    if len(idx) < 10:
        return PassScore(math.nan, math.nan, len(idx))
    k = as_measured(f.kin.take(idx))
    ce = CurrentEquations(model, k)
    a, b = ce.payload_equations(params.values)
    sig = (noise_sigma(params.current_noise, ce.currents(), ce.acc) if params.current_noise
           else np.broadcast_to(sigma0, a.shape))
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1) & np.isfinite(sig).all(axis=1)
    a, b, sig = a[ok], b[ok], sig[ok]
    aw, bw = a / sig, b / sig
    m_hat = float(np.sum(aw * bw) / np.sum(aw * aw))
    m = p.payload_kg if p.verified else m_hat
    e = (m * a - b) / sigma0
    # How far the calibration's own uncertainty moves this estimate (as the engine's
    # param_std_kg): m = sum(a b w) / sum(a a w), and the residual moves with p.
    jac = ce.jacobian(params.values, m_hat)[ok] / sig[:, :, None]
    g = -np.einsum("ke,kep->p", aw, jac) / np.sum(aw * aw)
    cal = math.sqrt(max(0.0, float(g @ params.cov @ g)))
    return PassScore(float(np.mean(np.sum(e * e, axis=1))), m_hat, int(ok.sum()), cal)


def evaluate(dataset: DataSet, effects: list[str], hyper: dict[str, dict[str, Any]],
             sigma0: np.ndarray, valid_ref: list[np.ndarray], method: str = "output",
             final: bool = False, fold_hyper: list[dict[str, dict[str, Any]]] | None = None,
             folds: bool = False) -> Evaluation:
    """Fit and judge base + ``effects`` on held-out passes (see the module doc).

    ``fold_hyper`` gives, per fold, hyper-parameters already found on that fold's
    training data (by the model this one extends), so they are not searched again.
    ``folds``: identify on the trials plus the other folds' verified passes even if the
    trials alone would do (the reference a cross-validated candidate is judged against).
    """
    passes = dataset.passes
    model = Model.from_names(effects, hyper)
    cv = folds or needs_operation(model, dataset)
    n_ver = sum(p.verified for p in passes)
    if cv and n_ver < 2:
        raise ValueError(f"{effects}: the calibration trials do not swing and fewer than two "
                         "measured passes have a verified payload; cannot identify it")
    if not cv:
        params = fit(dataset, effects, hyper, None, method)
        fold_of = {p.index: 0 for p in passes}
        fitted = [params]
    else:
        k = min(N_FOLDS, n_ver)
        fold_of = assign_folds(passes, k)
        fitted = []
        for j in range(k):
            train = {p.index for p in passes if p.verified and fold_of[p.index] != j}
            h = {**{e: dict(v) for e, v in (fold_hyper[j] if fold_hyper and j < len(
                fold_hyper) else {}).items() if e in effects}, **hyper}
            fitted.append(fit(dataset, effects, h, train, method))
    scores = {p.index: score_pass(fitted[fold_of[p.index]], dataset, p, sigma0, valid_ref)
              for p in passes}
    ev = Evaluation(list(effects), fitted, fold_of, scores, cv)
    if final:
        ev.final = fitted[0] if not cv else fit(
            dataset, effects, hyper, {p.index for p in passes if p.verified}, method)
    return ev
