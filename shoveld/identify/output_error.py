"""Output-error identification: the currents are the outputs, weighted by their noise.

Minimises, over all parameters at once (the mechanics, the hoist's pull per ampere
over the field current, the crowd's, and the current sensors' offsets), the sum of
squared differences between measured and predicted hoist and crowd currents
(``shoveld.model.output``), each divided by its channel's noise. The noise model
per channel (a floor, a part growing with the reading, parts growing with the
joints' accelerations, where the rates estimated from the angles are least exact)
is estimated from the residuals and the fit repeated with it (iteratively
reweighted). Gauss-Newton from the equation-error solution; the problem is nearly
linear, so a few steps converge.

Some inputs of the equations are measured, not known: the hoist field current,
through K_H(i_f), and the rates and accelerations smoothed from the noisy angle and
extension readings. Their noise biased the field curve's knots by up to 0.6 standard
errors and K_C by 0.5, so the final steps solve a corrected score that takes out its
expected part (:func:`input_noise_correction`), with each reading's noise read from
its own column (:func:`field_noise_a`, ``calibrate.position_noise_errors``).

Standard errors are the sandwich (heteroscedasticity and autocorrelation robust)
estimate over blocks of a few seconds: samples at 50 Hz are not independent, and a
covariance that pretends they are claims far too much. To it is added what no block
can see: the handle-angle sensor drifts by tenths of a degree over minutes, longer than
a calibration file, so within a file it acts as an unknown offset of the angle. Its
effect on the parameters (the fit's sensitivity to an offset of each file's angle,
times the drift's size) is a "consider" covariance, as orbit determination treats a
known-but-unestimated error. Without it, over 120 simulated machines MdLc, i_H0, i_C0
and J lay within 2 standard errors of the truth in only 79-86 % of them; with the
drift switched off in the simulator, in 91-96 %.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

from shoveld.identify import ANGLE_DRIFT_DEG
from shoveld.kinematics.offline import difference_noise, smoothed_noise_sd
from shoveld.model.kin import Kinematics
from shoveld.model.model import Model
from shoveld.model.output import CHANNELS, NOISE_KEYS, CurrentEquations, noise_regressors

BLOCK_S = 4.0
RUNAWAY_SE = 50.0
"""The corrected score's solution may move a parameter by at most this many white-noise
standard errors from the uncorrected one (the correction moves them by a few at twice
the simulator's angle noise; a runaway by 1e250)."""
"""Length of the blocks over which residual scores are summed for the covariance."""


@dataclass
class OutputFit:
    p: np.ndarray
    cov: np.ndarray
    noise: dict[str, dict[str, float]]
    """Per channel, the noise model (``shoveld.model.output.NOISE_KEYS``)."""
    residual_rms: dict[str, float]
    """Per channel, A."""
    force_rms: dict[str, float]
    """The same residuals in the equations' own units (N m, N)."""
    condition_number: float
    samples: int
    iterations: int
    blocks: int
    angle_sensitivity: np.ndarray
    """(files, parameters): parameter change per radian of offset of a file's handle
    angle; its outer product times the drift's variance is in ``cov``."""
    corrected: bool = False
    """Whether the inputs' noise was taken out (False: none given, or the corrected
    steps diverged and the uncorrected fit was kept)."""
    row_residuals: np.ndarray | None = None
    """(N, 2) A: each used sample's hoist and crowd current residual, NaN where the
    channel is not used (what a search over a hyper-parameter sums block by block)."""


def concat_kinematics(parts: list[Kinematics]) -> Kinematics:
    names = [f.name for f in fields(Kinematics) if f.init]
    return Kinematics(**{n: np.concatenate([getattr(k, n) for k in parts]) for n in names})


def _noise_model(r: np.ndarray, reg: np.ndarray) -> np.ndarray:
    """Coefficients c >= 0 with r^2 ~ reg @ c (non-negative least squares), floor > 0."""
    from scipy.optimize import nnls

    scale = np.linalg.norm(reg, axis=0)
    scale[scale == 0] = 1.0
    # the same problem on the QR factor: 4 x 4 instead of N x 4
    q, rr = np.linalg.qr(reg / scale)
    coef, _ = nnls(rr, q.T @ (r * r))
    coef = coef / scale
    coef[0] = max(coef[0], 1e-6)
    return coef


def angle_sensitivity(model: Model, k: Kinematics, m: np.ndarray, p: np.ndarray,
                      r: np.ndarray, good: np.ndarray, w: np.ndarray, h_inv_jt: np.ndarray,
                      lengths: list[int]) -> np.ndarray:
    """(files, parameters): how the fitted parameters move per radian of offset of each
    file's handle angle (one Gauss-Newton step from the solution: exact for a small
    offset, the problem being nearly linear)."""
    delta = 1e-4
    out = np.zeros((len(lengths), len(p)))
    start = 0
    for i, n in enumerate(lengths):
        shift = np.zeros(len(k.th))
        shift[start:start + n] = delta
        start += n
        dr = CurrentEquations(model, replace(k, th=k.th + shift)).residual(p, m) - r
        drw = np.where(good & np.isfinite(dr), dr, 0.0) * w
        out[i] = -(h_inv_jt @ drw.reshape(-1)) / delta
    return out


def field_noise_a(i_hf: np.ndarray) -> float:
    """The field-current channel's white noise (A, 1 sigma), from its second differences.

    The field winding's inductance keeps the true current smooth (time constants of
    tenths of a second against 50 Hz samples), so a second difference is noise (its
    variance 6 sigma^2) except at the few kinks where the drive changes its setpoint;
    the median ignores those."""
    return difference_noise(i_hf, 2)


@dataclass(frozen=True)
class InputError:
    """One independent error pattern of the measured inputs of the equations.

    ``shift``: how much each ``Kinematics`` field moves per unit of the error (a number,
    or one per sample); ``variance``: the error's variance in those units; ``step``:
    the finite-difference step (units) with which its effect on the equations is taken.
    """

    shift: dict[str, float | np.ndarray]
    variance: float = 1.0
    step: float = 1.0
    stride: int = 1
    """Take the expectation on every ``stride``-th sample, each standing for its
    neighbours (it is a smooth function of the motion; the cost is the equations'
    evaluation on the data moved by the error)."""


def field_error(sigma_a: float) -> InputError:
    """The field-current reading's noise as an input error (the step is half an ampere,
    small against the curve's knot spacing of 10 A)."""
    return InputError({"i_hf": 1.0}, sigma_a**2, 0.5)


def rate_errors(sigma: float, fields: tuple[str, str], dt: float, window: int,
                polyorder: int) -> list[InputError]:
    """A position reading's white noise ``sigma`` as the errors it leaves in the rate and
    the acceleration smoothed from it (``fields``), independent of each other.

    The smoothed value's own error (0.3 of ``sigma``: 0.009 deg on the handle)
    is left out: on one machine it moved no parameter by more than 0.2 % of what the
    rate's and the acceleration's errors move it, and each error costs two evaluations
    of the equations' Jacobian."""
    _, sd_rate, sd_acc = smoothed_noise_sd(sigma, dt, window, polyorder)
    return [InputError({f: 1.0}, sd * sd, sd) for f, sd in zip(fields, (sd_rate, sd_acc),
                                                               strict=True)]


def input_noise_correction(model: Model, k: Kinematics, ce: CurrentEquations, p: np.ndarray,
                           m: np.ndarray, w2: np.ndarray, errors: list[InputError]
                           ) -> np.ndarray:
    """(parameters,) the expected part of the weighted score sum w^2 J r that noise in
    the measured inputs causes at the true parameters, to subtract from it (a corrected
    score for errors in variables).

    The predicted currents depend on measured inputs (the field current through
    K_H(i_f); the angles and their smoothed rates and accelerations through every
    term), so an input's noise u is in both the residual r and its Jacobian J. To
    second order in u, with r', r'' and J' the derivatives along the error,
    E[J r] = (J r''/2 + J' r') var(u), summed over independent errors. Left in, the
    field reading's noise pulled the lowest and highest field knots by about 0.6
    standard errors over 120 simulated machines, and the angles' noise K_C by 0.5.
    """
    total = np.zeros(len(p))
    for stride in sorted({e.stride for e in errors}):
        if stride == 1:
            k_s, ce_s, m_s, w2_s = k, ce, m, w2
        else:
            idx = np.arange(0, len(m), stride)
            k_s, m_s, w2_s = k.take(idx), m[idx], w2[idx] * stride
            ce_s = CurrentEquations(model, k_s)
        jac = ce_s.jacobian(p, m_s)
        r0 = ce_s.residual(p, m_s)
        for e in (e for e in errors if e.stride == stride):
            h = e.step
            moved = [CurrentEquations(model, replace(k_s, **{
                f: getattr(k_s, f) + sign * h * (a[::stride] if isinstance(a, np.ndarray) else a)
                for f, a in e.shift.items()})) for sign in (1.0, -1.0)]
            rp, rm = (c.residual(p, m_s) for c in moved)
            r1 = (rp - rm) / (2 * h)
            r2 = (rp - 2 * r0 + rm) / (h * h)
            j1 = (moved[0].jacobian(p, m_s) - moved[1].jacobian(p, m_s)) / (2 * h)
            term = (jac * (0.5 * r2)[:, :, None] + j1 * r1[:, :, None]) * w2_s[:, :, None]
            total += np.einsum("kep->p", np.where(np.isfinite(term), term, 0.0)) * e.variance
    return total


def fit_output(model: Model, kins: list[Kinematics], payloads: list[np.ndarray],
               row_ok: list[np.ndarray], p0: np.ndarray, max_iter: int = 25,
               angle_drift_deg: float = ANGLE_DRIFT_DEG, field_noise: float = 0.0,
               input_errors: Sequence[InputError] = ()) -> OutputFit:
    """Fit ``model`` to the used samples of each file (kinematics ``kins``, known
    payloads, and per-sample per-channel masks ``row_ok``), starting from ``p0``;
    ``angle_drift_deg``: the handle-angle sensor's drift within a file (1 sigma), whose
    effect is added to the covariance (0: not); ``field_noise``: the field-current
    channel's noise (A, 1 sigma: :func:`field_noise_a`), whose bias on the fit is
    removed (0: not); ``input_errors``: other noise in the inputs (the angles':
    :func:`rate_errors`), whose bias is removed likewise."""
    k = concat_kinematics(kins)
    m = np.concatenate(payloads)
    ok = np.concatenate(row_ok).astype(bool)
    ce = CurrentEquations(model, k)
    reg = noise_regressors(ce.currents(), np.nan_to_num(ce.acc))
    blocks = np.concatenate([fi * 1_000_000 + np.floor((kk.t - kk.t[0]) / BLOCK_S)
                             for fi, kk in enumerate(kins)]).astype(np.int64)
    n_p = len(p0)
    p = np.asarray(p0, dtype=float).copy()
    off = model.offset_index
    if off is not None:
        p[list(off)] = 0.0

    def weighted(p: np.ndarray, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = ce.residual(p, m)
        good = ok & np.isfinite(r)
        w = np.where(good, 1.0 / sig, 0.0)
        return np.where(good, r, 0.0) * w, w

    def gauss_newton(p: np.ndarray, sig: np.ndarray, correction: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """The Gauss-Newton step of the weighted fit at ``p`` (of the score less
        ``correction``, if given), columns scaled to unit norm; and the weighted
        residual there."""
        rw, w = weighted(p, sig)
        # The Jacobian is the fit's largest array (N x 2 x P), made every step: weighted
        # in place, and read twice more, by the two products (the columns' norms are the
        # normal matrix's diagonal). Its rows in the order they lie in memory (channel by
        # channel: a view, not a copy), the residuals in the same order.
        jw = ce.jacobian(p, m)
        jw *= w[:, :, None]
        if not math.isfinite(float(jw.sum())):  # rows left out (w = 0) of unusable input
            np.copyto(jw, 0.0, where=~np.isfinite(jw))
        rows = jw.transpose(1, 0, 2).reshape(-1, n_p)
        normal = rows.T @ rows
        scale = np.sqrt(np.diag(normal))
        scale = np.where(scale == 0, 1.0, scale)
        g = (rows.T @ rw.T.reshape(-1)) / scale
        if correction is not None:
            g = g - correction / scale
        normal /= np.outer(scale, scale)
        return np.linalg.lstsq(normal, -g, rcond=None)[0] / scale, rw

    r0 = ce.residual(p, m)
    good0 = ok & np.isfinite(r0)
    sig = np.ones_like(r0) * np.array([np.sqrt(np.mean(r0[good0[:, j], j] ** 2))
                                       for j in range(2)])[None, :]
    iterations = 0
    for _outer in range(4):
        for _ in range(max_iter):
            iterations += 1
            step, rw = gauss_newton(p, sig)
            cost = float(np.sum(rw * rw))
            lam = 1.0
            while lam > 1e-4:
                rn, _ = weighted(p + lam * step, sig)
                if float(np.sum(rn * rn)) <= cost:
                    break
                lam *= 0.5
            p = p + lam * step
            if np.max(np.abs(lam * step) / (np.abs(p) + 1e-9)) < 1e-6:
                break
        r = ce.residual(p, m)
        good = ok & np.isfinite(r)
        new = np.empty_like(sig)
        noise: dict[str, dict[str, float]] = {}
        for j, ch in enumerate(CHANNELS):
            coef = _noise_model(r[good[:, j], j], reg[good[:, j], j])
            noise[ch] = {k: math.sqrt(c) for k, c in zip(NOISE_KEYS, coef, strict=False)}
            new[:, j] = np.sqrt(reg[:, j] @ coef)
        if np.max(np.abs(new[good] - sig[good]) / sig[good]) < 0.03:
            sig = new
            break
        sig = new

    corrected = False
    errors = list(input_errors)
    if field_noise > 0 and any(getattr(t, "uses_field_current", False)
                               for t in model.terms):
        errors.insert(0, field_error(field_noise))
    if errors:
        corrected = True
        # Solve the corrected score equations J'W r - correction = 0 by Gauss-Newton.
        # The problem is nearly linear and the correction small, so it is evaluated once,
        # at the uncorrected solution.
        # A model the data hardly determine (a diagnosis's candidate) can make these
        # steps grow without end; a fit whose steps do not converge, or converge far
        # away, keeps its uncorrected solution.
        _, w = weighted(p, sig)
        correction = input_noise_correction(model, k, ce, p, m, w * w, errors)
        plain, converged = p, False
        for _ in range(max_iter):
            iterations += 1
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                step, _ = gauss_newton(p, sig, correction)  # overflows are caught below
                p = p + step
                rel = float(np.max(np.abs(step) / (np.abs(p) + 1e-9)))
            if not math.isfinite(rel):
                break
            if rel < 1e-7:
                converged = True
                break
        if converged:
            # a solution far beyond the data's own precision is a runaway, not a correction
            _, w = weighted(plain, sig)
            jw = np.where(np.isfinite(jac := ce.jacobian(plain, m)), jac, 0.0) * w[:, :, None]
            jr = jw.reshape(-1, n_p)
            se = np.sqrt(np.abs(np.diag(np.linalg.pinv(jr.T @ jr)))) + 1e-12
            with np.errstate(over="ignore"):  # a runaway's step overflows: inf is "not converged"
                converged = float(np.max(np.abs(p - plain) / se)) < RUNAWAY_SE
        if not converged:
            p, corrected = plain, False

    rw, w = weighted(p, sig)
    jac = ce.jacobian(p, m)
    jw = np.where(np.isfinite(jac), jac, 0.0) * w[:, :, None]
    jac_rows = jw.reshape(-1, n_p)
    h = jac_rows.T @ jac_rows
    h_inv = np.linalg.pinv(h)
    # Sandwich: scores summed per block, so correlation within a block is counted.
    scores = np.einsum("kep,ke->kp", jw, rw)
    ids, inv = np.unique(blocks, return_inverse=True)
    s_b = np.zeros((len(ids), n_p))
    np.add.at(s_b, inv, scores)
    nb = len(ids)
    v = s_b.T @ s_b * (nb / max(1, nb - n_p))
    cov = h_inv @ v @ h_inv
    r = ce.residual(p, m)
    good = ok & np.isfinite(r)
    sens = angle_sensitivity(model, k, m, p, r, good, w, h_inv @ jac_rows.T,
                             [len(kk) for kk in kins])
    cov = cov + sens.T @ sens * math.radians(angle_drift_deg) ** 2
    # Residuals are correlated over the smoothing window (and the model's own misfit is
    # smooth): a pass's payload, a weighted sum over its samples, varies by the
    # integrated autocorrelation time more than white noise would.
    from shoveld.identify.calibrate import integrated_autocorrelation

    z = r / sig
    starts = np.cumsum([0] + [len(kk) for kk in kins])
    for j, ch in enumerate(CHANNELS):
        taus, lens = [], []
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            zz = z[a:b, j][good[a:b, j]]
            if len(zz) > 50:
                taus.append(integrated_autocorrelation(zz))
                lens.append(len(zz))
        noise[ch]["tau"] = float(np.average(taus, weights=lens)) if taus else 1.0
    g_h, _, g_c = ce.gains(p)
    norms = np.linalg.norm(jac_rows, axis=0)
    sv = np.linalg.svd(jac_rows / np.where(norms > 0, norms, 1.0), compute_uv=False)
    return OutputFit(
        p=p, cov=cov, noise=noise,
        residual_rms={ch: float(np.sqrt(np.mean(r[good[:, j], j] ** 2)))
                      for j, ch in enumerate(CHANNELS)},
        force_rms={"handle": float(np.sqrt(np.mean((r[:, 0] * g_h)[good[:, 0]] ** 2))),
                   "crowd": float(np.sqrt(np.mean((r[:, 1] * g_c)[good[:, 1]] ** 2)))},
        condition_number=float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf,
        samples=int(len(m)), iterations=iterations, blocks=nb, angle_sensitivity=sens,
        corrected=corrected, row_residuals=np.where(good, r, np.nan))
