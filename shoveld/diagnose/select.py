"""Forward selection of physical extensions on held-out passes.

At each step every candidate not yet in the model is added on its own, identified,
and judged pass by pass on data it was not fitted on (``shoveld.diagnose.fit``).
Per pass, the log ratio of held-out losses (current model over candidate) is one
independent observation; their mean over the passes, against their spread, gives a
one-sided t statistic (for a term acting per kilogram of load, the slope of the log
ratios on the load squared: a light pass can show nothing of it). A candidate is
significant when

* t exceeds the Bonferroni-corrected critical value for the step (family-wise
  alpha over the candidates tried);
* it removes at least ``min_gain`` of the held-out residual (materiality: the base
  model's own approximations, e.g. its friction smoothing and the noise of the
  differentiated rates, are of about 1 % on simulated data without any hidden
  effect, and an extension smaller than that is not a finding);
* it pays for itself on the payload: over the verified held-out passes, the payload
  errors fall, by paired one-sided tests at ``payload_alpha`` (see ``_pays``; a term that
  fits the residual a little better but leaves the payload where it was is not named;
  on realistic machines the base model's own approximations leave a few percent of
  structured residual that a flexible term can always take); a candidate that removes
  a decisive share of the residual (``decisive_gain``) need only not make the payload
  significantly worse (``decisive_worse_alpha``), since a second effect may hold the
  payload until both are in the model;
* (optionally) it does not make the payload of the verified held-out passes worse by
  more than a multiple of the payload uncertainty of its own calibration.

A term the residual cannot see (``ExtensionTerm.residual_blind``: the rope's weight,
which the dipper's mass absorbs) that fails these tests is named on its physics instead
(``_blind_witness``): clear of zero on its physical side, and either its payload errors
fall significantly or its value holds beside the earlier steps' models.

A candidate identified with the verified passes is judged against the current model
identified on the same folds (``same_data``). The significant candidate with the largest
share of the residual is added (a decisive re-alignment of the streams in time first,
``align_first``; then one its physics confirms; beside a term named on another witness,
the lower payload RMS: ``_first``) and the search repeats; it stops
when none is significant ("nothing significant" is an answer). Then each term found is
judged again beside all the others, and one that no longer qualifies is removed
(``_backward``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from scipy import stats

from shoveld.diagnose.data import DataSet, Pass
from shoveld.diagnose.fit import Evaluation, evaluate
from shoveld.model.effects import ExtensionTerm
from shoveld.model.terms import TERMS
from shoveld.words import n_of

UNSTABLE = 1.0
"""A candidate whose held-out residual is more than (1 + this) times the current model's
has not fitted; it is reported as unstable, not ranked by its score."""
UNSTABLE_WHY = "unstable fit"
NOT_PHYSICAL = "not physical"
"""A candidate whose own parameter lies more than ``OUTSIDE_SE`` standard errors outside
its physical bounds (``ExtensionTerm.bounds``: a negative rope mass) stands in for
another cause; it is reported so, not ranked nor paired."""
OUTSIDE_SE = 3.0


@dataclass(frozen=True)
class SelectionConfig:
    alpha: float = 0.01
    """Family-wise false-alarm probability per step (Bonferroni over the candidates)."""
    min_gain: float = 0.02
    """Smallest relative reduction of the held-out residual that counts as a finding."""
    max_effects: int = 3
    pair_among: int = 3
    """Where no candidate is significant alone, pairs among this many of those that take
    at least ``min_gain`` of the residual are tried together, and a decisive one that
    fails only the payload test is tried beside every other (``_pair``); 0: never."""
    payload_alpha: float = 0.05
    """A candidate must cut the verified held-out passes' payload errors at this one-sided
    significance (t test on the squares or signed ranks of |e|, each at half of it;
    1.0: no payload test)."""
    decisive_gain: float = 0.10
    """A candidate that removes at least this share of the held-out residual need only not
    make the verified held-out passes' payload significantly worse
    (``decisive_worse_alpha``), instead of cutting their errors significantly
    (``payload_alpha``): the base model's own approximations leave a few
    percent of structured residual on a clean machine (the best candidate took at most
    1.0 % on the bench's ten clean machines, docs/diagnosis.md), so a share ten times
    that is no artefact, and with a second effect in the data the payload may improve
    only once both are in the model. inf: every candidate must pay."""
    decisive_worse_alpha: float = 0.05
    """A decisive candidate (``decisive_gain``) is refused only where its verified held-out
    passes' payload errors grow at this one-sided significance (``_pays`` the other way
    round), not at any rise of their RMS, which over a dozen passes is as likely as a
    fall where the term hardly moves the payload: a true time skew beside the saturation
    was refused on 83 -> 98 kg over 14 passes. On the saved sets 13-19 and both draws of
    the singles it named three more pairs right and changed no other name
    (docs/diagnosis.md, twenty-second session). 1.0: any rise refuses it (before)."""
    align_first: bool = True
    """A significant term that re-aligns the sensor streams in time
    (``ExtensionTerm.aligns_streams``: the time skew) and takes a decisive share of the
    residual (``decisive_gain``) is added before any other that qualifies at the same
    step, whatever their shares: a model term fitted on streams out of step takes part
    of the lag into its own shape (the saturation's knee took a 155-159 ms skew on two
    pairs of the twentieth set, and beside it the skew then failed the tests). A
    smaller share is ranked as any other (a spurious 60 ms laser lag took 6 % on a
    slope + saturation machine). On every saved case (pair sets 13-20, both draws of
    the singles) it changed one name, the friction + skew pair found; on two sets drawn
    after it, 15/15 as with it off, and 14/15 against 13/15, another friction + skew pair
    found (docs/diagnosis.md, twenty-third session). False: ranked by share only
    (before)."""
    delay_z: float = 5.0
    """A term that re-aligns the sensor streams (``aligns_streams``: the time skew),
    significant on the held-out residual but short of the decisive share, that fails
    only the payload test is named when the payload does not get worse and a device's
    lateness stands this many of its standard deviations (the search's own with the
    model error, ``findings``) clear of zero (witness "delay"): a stream's lateness
    moves the payload little on a lift, so a dozen verified passes cannot show it
    (a 168 ms skew beside the saturation: its share 7.5 %, t 3.09, 0.14 s +- 0.017 s
    found, the payload 129 -> 119 kg at p 0.4, removed), where the delay itself is a
    value no stand-in has reason to give clear of zero. inf: never (before)."""
    same_data: bool = True
    """Judge a candidate identified with the verified passes (it needs a full dipper or
    swinging, ``fit.needs_operation``) against the current model identified on the same
    folds, not on the trials alone, so that what the passes teach the base model's own
    parameters is not credited to the candidate's term (else the cubic saturation,
    fitted on the passes, stood in for friction, rope weight and slope). Measured with
    ``decisive_gain`` (docs/diagnosis.md, 2026-11-27): alone, it left the knee-shaped
    saturation unnamed, because the base identified with the passes already takes
    most of its payload error and the cubic's remaining gain is not significant."""
    blind_z: float = 5.0
    """A term the residual cannot see (``ExtensionTerm.residual_blind``) that fails the
    residual tests only by size (it moves the held-out residual by less than ``min_gain``
    either way) is named on the payload when each of its parameters stands this many
    standard errors from zero inside its physical bounds and the verified passes' payload
    errors fall (``payload_alpha``). Five, the usual bar for a discovery: on the bench the
    true rope weight stood 7-45 standard errors out, the rope term fitted to other causes
    at most 5.2 where the rule was written, and 5.3 once (a false name) on pairs drawn
    after it (docs/diagnosis.md). inf: never."""
    agree_se: float = 2.0
    """A term the residual cannot see that passes ``blind_z`` but not the payload test is
    also named when the verified passes' payload RMS falls and its value agrees, within
    this many standard errors of the difference, with its value beside each model of the
    earlier steps where that was physical and clear of zero (``_agrees``). The true rope
    moved by 0.1-1.8 of them between models on the bench; fitted to another cause it was
    clear of zero beside one model at most (docs/diagnosis.md). 0: never."""
    load_weighted: bool = True
    """A term acting per kilogram of load (``ExtensionTerm.per_load``) is tested on the
    passes weighted by their load squared, the share of its signal each can carry
    (``_load_weights``), instead of all alike: the load-dependent friction beside the
    swing's term took 1-4 % of the residual, most of it on the heaviest passes, and the
    light ones' noise held its plain t at 0.7-1.6. Over nine sets of pairs the true
    friction's t went from a median 4.2 to 7.3, an absent one's from 0.5 to 0.4
    (docs/diagnosis.md, fifteenth session)."""
    backward: bool = True
    """Once no candidate qualifies, each term found is judged again as if it came last:
    against the model without it (``compare``, the family the model's terms), and the
    least significant of those that no longer qualify is removed, the rest judged again
    (``_backward``). A term added early can stand in for causes found after it: the cubic
    saturation, named first on a rope + friction machine, for the friction it masks
    (docs/diagnosis.md). False: forward steps only."""
    payload_tolerance: float = math.inf
    """If finite, a candidate may not raise the held-out payload RMS error by more than
    this many times the payload uncertainty its own calibration implies. Off by
    default: two effects whose payload errors partly cancel would each look as if
    they did not pay until both are in the model; the payload is reported instead."""


@dataclass
class CandidateScore:
    name: str
    gain: float
    """Relative reduction of the held-out residual loss (0.1 = 10 % less)."""
    t: float
    t_crit: float
    passes: int
    payload_rms_kg: float
    payload_mean_kg: float
    payload_ratio: float
    """Held-out payload mean-square error relative to the current model's."""
    significant: bool
    why: str
    hyper: dict[str, Any]
    cross_validated: bool
    witness: str = "residual"
    """What named it: the held-out residual, the payload alone (``blind_z``), its value
    as its physics predicts ("prediction"), or its value agreeing beside the earlier
    models (``agree_se``)."""
    confirmed: bool = False
    """Its value came out as its physics predicts (``_confirmed``): named before the
    others that qualify at the same step."""

    def as_dict(self) -> dict[str, Any]:
        def r(x: float, n: int = 4) -> float | None:
            return None if not math.isfinite(x) else round(float(x), n)
        return {"name": self.name, "score": r(self.gain), "t": r(self.t, 2),
                "t_crit": r(self.t_crit, 2), "passes": self.passes,
                "payload_rms_kg": r(self.payload_rms_kg, 1),
                "payload_mean_kg": r(self.payload_mean_kg, 1),
                "payload_mse_ratio": r(self.payload_ratio, 3),
                "significant": self.significant, "why": self.why,
                "hyper": self.hyper, "cross_validated": self.cross_validated,
                "witness": self.witness, "confirmed": self.confirmed}


@dataclass
class Step:
    model: list[str]
    candidates: list[CandidateScore]
    chosen: str | None
    pairs: list[CandidateScore] = field(default_factory=list)
    """Pairs tried together where no candidate qualified alone (``_pair``)."""
    removed: str | None = None
    """A backward step (``_backward``): ``candidates`` are the model's terms judged each
    beside the others, and this one no longer qualified and was removed."""


@dataclass
class Selection:
    found: list[str]
    steps: list[Step]
    base: Evaluation
    extended: Evaluation
    evaluations: dict[tuple[str, ...], Evaluation] = field(default_factory=dict)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if len(x) else math.nan


def _pays(e0: np.ndarray, e1: np.ndarray, alpha: float) -> tuple[bool, float]:
    """Do the payload errors shrink, pass by pass? Two paired one-sided tests, each at
    alpha / 2 (so together at most alpha): a t test on the squared errors (the mean
    square falls, even if only the worst passes improve) and a Wilcoxon signed-rank test
    on |e0| - |e1| (most passes improve, even if one heavy pass swamps the squares).
    Returns the verdict and the smaller p value."""
    d2 = e0**2 - e1**2
    sd = float(d2.std(ddof=1))
    if sd > 0.0:
        t = float(d2.mean() / (sd / math.sqrt(len(d2))))
        p_t = float(stats.t.sf(t, len(d2) - 1))
    else:
        p_t = 0.0 if d2.mean() > 0 else 1.0
    d = np.abs(e0) - np.abs(e1)
    p_w = (float(stats.wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue)
           if np.any(d != 0.0) else 1.0)
    p = min(p_t, p_w)
    return p < alpha / 2.0, p


def _load_weights(cur: Evaluation, passes: list[Pass], name: str, cfg: SelectionConfig
                  ) -> np.ndarray:
    """Per pass, what a term acting per kilogram of load (``ExtensionTerm.per_load``) can
    show there: its currents grow with the load m, their square (the loss it removes)
    with m^2, so a light pass can witness nothing and only adds its noise to the mean.
    m is the scale's when verified, else the current model's estimate. Ones for any
    other term (or ``cfg.load_weighted`` off)."""
    if not (cfg.load_weighted and all(getattr(TERMS.get(t), "per_load", False)
                                      for t in name.split("+"))):
        return np.ones(len(passes))
    m = np.array([p.payload_kg if p.verified else cur.scores[p.index].payload_kg
                  for p in passes])
    m = np.where(np.isfinite(m), np.clip(m, 0.0, None), 0.0)
    top = float(m.max()) if len(m) else 0.0
    return (m / top) ** 2 if top > 0.0 else np.ones(len(passes))


def _t_through_origin(d: np.ndarray, x: np.ndarray) -> float:
    """t statistic of b in d = b x + noise (least squares through the origin): with x all
    ones, the one-sample t of the mean of d. The matched filter for a gain expected to
    grow as x from pass to pass."""
    n = len(d)
    sxx = float(x @ x)
    if n < 2 or sxx <= 0.0:
        return math.inf if n > 1 and d.mean() > 0 else -math.inf
    b = float(x @ d) / sxx
    s2 = float(np.sum((d - b * x) ** 2)) / (n - 1)
    if s2 <= 0.0:
        return math.inf if b > 0 else -math.inf
    return b / math.sqrt(s2 / sxx)


def compare(dataset: DataSet, cur: Evaluation, cand: Evaluation, name: str, n_tried: int,
            cfg: SelectionConfig, before: Sequence[Evaluation] = ()) -> CandidateScore:
    """Score ``cand`` against ``cur`` on the passes both could judge. ``before``: the same
    term's fits beside the models of the earlier steps (``_agrees``)."""
    passes = [p for p in dataset.passes
              if math.isfinite(cur.scores[p.index].loss)
              and math.isfinite(cand.scores[p.index].loss)]
    l0 = np.array([cur.scores[p.index].loss for p in passes])
    l1 = np.array([cand.scores[p.index].loss for p in passes])
    n = len(l0)
    gain = float((l0 - l1).mean() / l0.mean()) if n else math.nan
    # Per pass, the log of the loss ratio: scale-free, so a few heavy passes with large
    # residuals do not swamp the spread (their improvements differ in size, not in sign).
    d = np.log(l0 / l1)
    t = _t_through_origin(d, _load_weights(cur, passes, name, cfg))
    t_crit = float(stats.t.ppf(1.0 - cfg.alpha / max(1, n_tried), max(1, n - 1)))
    e0 = np.array([cur.scores[p.index].payload_kg - p.payload_kg for p in passes if p.verified])
    e1 = np.array([cand.scores[p.index].payload_kg - p.payload_kg for p in passes
                   if p.verified])
    ratio = float(np.mean(e1**2) / np.mean(e0**2)) if len(e0) else math.nan
    # The payload may move by its calibration uncertainty (common to all passes, so not
    # averaged away) without counting against the model.
    cal = float(np.mean([cand.scores[p.index].calib_std_kg for p in passes if p.verified])
                ) if len(e0) else 0.0
    worse = _rms(e1) - _rms(e0) if len(e0) else 0.0
    why = ""
    if math.isfinite(gain) and gain < -UNSTABLE:
        # The candidate's own fit is off (its parameters wander on data that does not
        # excite them): not a finding either way, and its score says nothing.
        why = f"{UNSTABLE_WHY} (held-out residual {1 - gain:.1f} x the current model's)"
    elif outside := _outside_bounds(cand, name):
        why = f"{NOT_PHYSICAL} ({outside}: it stands in for another cause)"
    elif not (t > t_crit):
        why = f"not significant (t {t:.2f} <= {t_crit:.2f})"
    elif not (gain >= cfg.min_gain):
        why = f"too small ({100 * gain:.1f} % < {100 * cfg.min_gain:.0f} % of the residual)"
    elif (len(e0) > 2 and cfg.payload_alpha < 1.0 and gain >= cfg.decisive_gain
          and not _rms(e1) <= _rms(e0) and (
              cfg.decisive_worse_alpha >= 1.0
              or (rises := _pays(e1, e0, cfg.decisive_worse_alpha))[0])):
        why = (f"does not pay on the payload: its held-out RMS rises ({_rms(e0):.0f} -> "
               f"{_rms(e1):.0f} kg over {n_of(len(e0), 'verified pass', 'verified passes')}"
               + (f", p {rises[1]:.2g})" if cfg.decisive_worse_alpha < 1.0 else ")"))
    elif len(e0) > 2 and cfg.payload_alpha < 1.0 and gain < cfg.decisive_gain and not (
            pays := _pays(e0, e1, cfg.payload_alpha))[0]:
        why = (f"does not pay on the payload (held-out RMS {_rms(e0):.0f} -> {_rms(e1):.0f} kg"
               f" over {n_of(len(e0), 'verified pass', 'verified passes')}, p {pays[1]:.2g})")
    elif len(e0) and worse > cfg.payload_tolerance * cal:
        why = (f"does not pay (held-out payload RMS {worse:+.0f} kg, more than "
               f"{cfg.payload_tolerance:g} x its calibration uncertainty {cal:.0f} kg)")
    witness = "residual"
    if (why.startswith(PAYLOAD_ONLY) and gain < cfg.decisive_gain and _rms(e1) <= _rms(e0)
            and _late_clear(cand, name, cfg.delay_z)):
        why, witness = "", "delay"
    confirmed = name in TERMS and _confirmed(cand, TERMS[name], cfg)
    if why.startswith(("not significant", "too small", PAYLOAD_ONLY)) and (
            blind := _blind_witness(cand, name, gain, e0, e1, cfg, before, confirmed)):
        why, witness = "", blind
    hyper = ({n: dict(cand.hyper().get(n, {})) for n in name.split("+")} if "+" in name
             else dict(cand.hyper().get(name, {})))
    return CandidateScore(name, gain, t, t_crit, n, _rms(e1),
                          float(e1.mean()) if len(e1) else math.nan, ratio, not why, why,
                          hyper, cand.cross_validated, witness, confirmed)


def _estimate(cand: Evaluation, param: str) -> tuple[float, float] | None:
    """``param``'s identified value and standard error in ``cand``'s fit (the final one,
    else the first fold's); None where the fit has no such parameter."""
    fitted = cand.final or cand.folds[0]
    if param not in fitted.names:
        return None
    i = fitted.names.index(param)
    return float(fitted.values[i]), float(fitted.stderr[i])


def _outside_bounds(cand: Evaluation, name: str) -> str:
    """The first own parameter of ``name``'s terms that lies more than ``OUTSIDE_SE``
    standard errors outside its physical bounds, in words; "" if none. The rope's term
    fitted where a slope or a saturation is the cause gave -600 to -184 kg/m, 6-13
    standard errors below zero (docs/diagnosis.md)."""
    for term_name in name.split("+"):
        for p, (lo, hi) in getattr(TERMS.get(term_name), "bounds", {}).items():
            if (est := _estimate(cand, p)) is None:
                continue
            v, se = est
            if v < lo - OUTSIDE_SE * se or v > hi + OUTSIDE_SE * se:
                return f"{p} {v:.4g} +- {se:.2g}, outside [{lo:g}, {hi:g}]"
    return ""


def _blind_witness(cand: Evaluation, name: str, gain: float, e0: np.ndarray,
                   e1: np.ndarray, cfg: SelectionConfig, before: Sequence[Evaluation] = (),
                   confirmed: bool = False) -> str:
    """What names ``name``, a term the residual cannot see (``residual_blind``, or beside
    a term that masks it, ``masked_by``, or ``confirmed``: its value came out as its
    physics predicts, ``_confirmed``), that failed the residual or the payload tests: "payload",
    "prediction" (confirmed, and the verified passes' payload RMS falls), "agreement", or
    "" (not named).

    Each own parameter must stand ``blind_z`` standard errors from zero inside the term's
    physical bounds, and the held-out residual must not be worse by ``min_gain``. Then
    either its share of the residual is under ``min_gain`` either way (any share, beside
    a term that masks it) and the verified passes' payload errors fall significantly
    (``payload_alpha``: "payload"), or their RMS falls and the same value was found
    beside each model of the earlier steps where it was physical (``_agrees``:
    "agreement"). Fitted to another cause the rope's weight came out negative (as a
    slope or a saturation), within 5 standard errors of zero but once, and moved with the
    model around it (docs/diagnosis.md)."""
    term = TERMS.get(name)
    if term is None or len(e0) <= 2 or not gain > -cfg.min_gain:
        return ""
    masked = confirmed or any(e in getattr(term, "masked_by", ()) for e in cand.effects)
    if not (getattr(term, "residual_blind", False) or masked):
        return ""
    now = {p: est for p in term.params if (est := _estimate(cand, p)) is not None}
    bounds = getattr(term, "bounds", {})
    if len(now) < len(term.params) or not all(
            _clear(est, bounds.get(p), cfg.blind_z) for p, est in now.items()):
        return ""
    if confirmed and _rms(e1) < _rms(e0):
        return "prediction"
    if (abs(gain) < cfg.min_gain or masked) and _pays(e0, e1, cfg.payload_alpha)[0]:
        return "payload"
    if _rms(e1) < _rms(e0) and _agrees(name, now, before, cfg):
        return "agreement"
    return ""


def _late_clear(cand: Evaluation, name: str, z: float) -> bool:
    """Does ``name``, a term that re-aligns the streams, find some device late by ``z``
    of its standard deviations (the search's own and the model error, as the report
    gives them) or more?"""
    if not (math.isfinite(z) and getattr(TERMS.get(name), "aligns_streams", False)):
        return False
    fitted = cand.final or cand.folds[0]
    for t in fitted.model().terms:
        if t.name == name:
            assert isinstance(t, ExtensionTerm)  # ``aligns_streams`` is an ExtensionTerm's
            return any(f["std"] > 0.0 and f["value"] >= z * f["std"]
                       for f in t.findings(fitted.names, fitted.values, fitted.cov))
    return False


def _confirmed(cand: Evaluation, term: Any, cfg: SelectionConfig) -> bool:
    """Does each of the term's ``predicted`` parameters come out as physics predicts: its
    ratio to the base parameter inside the range, ``blind_z`` standard errors clear of
    zero? Then the cause is confirmed by a value no stand-in has reason to give (the
    slope's kappa: 1 for a true slope), and the residual's verdict on its share does
    not decide (``_blind_witness``)."""
    pred = getattr(term, "predicted", {})
    if not pred:
        return False
    for p, (ref, lo, hi) in pred.items():
        if (est := _estimate(cand, p)) is None or (base := _estimate(cand, ref)) is None:
            return False
        v, b = est[0], base[0]
        if not (b > 0.0 and lo <= v / b <= hi and _clear(est, None, cfg.blind_z)):
            return False
    return True


def _clear(est: tuple[float, float], bounds: tuple[float, float] | None, z: float) -> bool:
    """Does the estimate (value, standard error) stand ``z`` standard errors from zero
    inside ``bounds``?"""
    (v, se), (lo, hi) = est, bounds or (-math.inf, math.inf)
    return lo <= v <= hi and se > 0.0 and abs(v) >= z * se


def _agrees(name: str, now: dict[str, tuple[float, float]], before: Sequence[Evaluation],
            cfg: SelectionConfig) -> bool:
    """Was ``name``'s value (``now``: parameter -> value, standard error) found beside each
    model of the earlier steps where it is physical, clear of zero (``blind_z``) and
    within ``agree_se`` standard errors of the difference? At least one such model is
    needed. A weight the machine has does not depend on what else is modelled; a term
    standing in for another cause takes what the other terms leave, so it moves as they
    come in (the rope beside a slope and a swing: -415 kg/m alone, +66 beside both),
    or comes out impossible, and such a model is skipped (``_outside_bounds``)."""
    if not cfg.agree_se > 0.0:
        return False
    bounds = getattr(TERMS.get(name), "bounds", {})
    seen = 0
    for ev in before:
        then = {p: est for p in now if (est := _estimate(ev, p)) is not None}
        if len(then) < len(now) or _outside_bounds(ev, name):
            continue
        for p, (v, se) in now.items():
            v0, se0 = then[p]
            if not (_clear(then[p], bounds.get(p), cfg.blind_z)
                    and abs(v - v0) <= cfg.agree_se * math.hypot(se, se0)):
                return False
        seen += 1
    return seen > 0


PAYLOAD_ONLY = "does not pay on the payload"
FOLDS = "@folds"
"""Marks a cache key whose model was identified on the folds' verified passes although
the trials alone would do (``SelectionConfig.same_data``)."""


def _cache_key(effects: list[str], folds: bool) -> tuple[str, ...]:
    """The key of the model with ``effects`` in ``forward_select``'s cache."""
    return (*effects, FOLDS) if folds else tuple(effects)


def _first(scores: Sequence[CandidateScore], cfg: SelectionConfig) -> CandidateScore | None:
    """The significant candidate a step adds (``scores`` sorted by their share of the
    residual): a decisive re-alignment of the streams first (``cfg.align_first``), then
    one its physics confirms (``_confirmed``), else the largest share,
    unless a term the residual cannot judge (named on another witness: the payload, its
    value's agreement) is significant beside it. A share cannot rank what the residual
    cannot see, so then the two are ranked on what both were judged on, the verified
    held-out passes' payload RMS: beside the saturation the boom's pose-shaped term took
    2.4 % of the residual (292 kg) where the friction it masks took none (232 kg), and
    named first the boom's term kept the friction out (docs/diagnosis.md)."""
    if cfg.align_first:
        for s in scores:
            if s.significant and s.gain >= cfg.decisive_gain and getattr(
                    TERMS.get(s.name), "aligns_streams", False):
                return s
    sig = sorted((s for s in scores if s.significant), key=lambda s: not s.confirmed)
    if not sig or sig[0].confirmed or sig[0].witness != "residual":
        return sig[0] if sig else None
    unseen = [s for s in sig if s.witness != "residual"]
    return min([sig[0], *unseen], key=lambda s: s.payload_rms_kg
               if math.isfinite(s.payload_rms_kg) else math.inf)


def _reference(cfg: SelectionConfig, cand: Evaluation, plain: Evaluation,
               refit: Callable[[], Evaluation]) -> Evaluation:
    """What ``cand`` is judged against: ``plain``, or, when the candidate was identified
    on the folds' verified passes and ``plain`` was not, the same model as ``plain``
    identified there too (``same_data``), so that a candidate is not credited with what
    the passes teach any model."""
    if cfg.same_data and cand.cross_validated and not plain.cross_validated:
        return refit()
    return plain


def _pairs_to_try(scores: list[CandidateScore], cfg: SelectionConfig
                  ) -> list[tuple[CandidateScore, CandidateScore]]:
    """The pairs ``_pair`` fits: among the best ``cfg.pair_among`` candidates by their share
    of the residual (each at least ``min_gain``, whatever test it failed alone), and each
    decisive or confirmed (``_confirmed``) candidate that failed only the payload test
    beside every other one; beside a confirmed one also those that came out not physical
    alone (a term standing in for another cause may be physical beside it: the rope's
    weight came out negative alone on four slope + rope machines, where the slope alone
    raised the payload RMS).

    Two effects at once can hide each other: the friction and the slope each took 8-16 %
    of the residual with a pass-to-pass spread too wide for significance alone, and
    together 29 %; beside a knee-shaped saturation the slope's term made the residual
    worse alone (the saturation's misfit dwarfs its share), while the saturation alone
    took half the residual and pushed the payload 525 kg high (docs/diagnosis.md)."""
    if cfg.pair_among <= 0:
        return []
    stable = [s for s in scores if math.isfinite(s.gain) and not s.why.startswith(UNSTABLE_WHY)]
    usable = [s for s in stable if not s.why.startswith(NOT_PHYSICAL)]
    pool = [s for s in usable if s.gain >= cfg.min_gain][:cfg.pair_among]
    pairs = [(a, b) for k, a in enumerate(pool) for b in pool[k + 1:]]
    for a in usable:
        if a.why.startswith(PAYLOAD_ONLY) and (a.gain >= cfg.decisive_gain or a.confirmed):
            # beside a confirmed cause also those not physical alone: they may have stood
            # in for it
            pairs += [(a, b) for b in (stable if a.confirmed else usable) if b is not a
                      and not any({a.name, b.name} == {x.name, y.name} for x, y in pairs)]
    return pairs


def _pair(dataset: DataSet, cur: Evaluation, scores: list[CandidateScore],
          cfg: SelectionConfig, n_single: int, fit: Any
          ) -> tuple[CandidateScore | None, list[CandidateScore]]:
    """Two candidates that each fail alone are tried together (``_pairs_to_try``): where
    two effects act at once, a model with one of them moves the payload towards the
    other's error, or leaves the other's share hidden in the spread, and only both in
    the model show the gain. The pair must be significant and pay on the payload, with
    the Bonferroni correction counting the pairs beside the single candidates. Each term
    of a pair must also earn its place beside the other, by the residual tests a next
    step would apply (significant, and at least ``min_gain`` of what the other leaves, or
    named beside it by its witness, ``_blind_witness``): else a term that fails alone
    would bring in a passenger."""
    pairs = _pairs_to_try(scores, cfg)
    n_tried = n_single + len(pairs)
    best: CandidateScore | None = None
    tried: list[CandidateScore] = []

    for a, b in pairs:
        names = [a.name, b.name]
        both = fit(names)
        s = compare(dataset, _reference(cfg, both, cur, lambda: fit([], True)), both,
                    "+".join(names), n_tried, cfg)
        for one, other in ((a.name, b.name), (b.name, a.name)):
            alone = _reference(cfg, both, fit([other]), partial(fit, [other], True))
            inc = compare(dataset, alone, both, one, n_tried, cfg)
            adds = (inc.t > inc.t_crit and inc.gain >= cfg.min_gain) or (
                inc.significant and inc.witness != "residual")
            if s.significant and not adds:
                s.significant = False
                s.why = (f"{one} adds {100 * inc.gain:.1f} % (t {inc.t:.2f}) to {other}: "
                         f"not significant beside it")
        tried.append(s)
        if s.significant and (best is None or s.gain > best.gain):
            best = s
    return best, tried


def forward_select(dataset: DataSet, library: list[str], sigma0: np.ndarray,
                   valid_ref: list[np.ndarray], cfg: SelectionConfig | None = None,
                   method: str = "output",
                   cache: dict[tuple[str, ...], Evaluation] | None = None) -> Selection:
    """Add the most effective significant candidate while one is significant.

    ``cache``: evaluations already fitted on this dataset, by their effects (a former
    run's ``Selection.evaluations``), so the bench can judge other selection rules on
    the same fits; it is filled as models are fitted."""
    cfg = cfg or SelectionConfig()
    cache = {} if cache is None else cache
    fixed_hyper: dict[str, dict[str, Any]] = {}
    for key, done in cache.items():
        if not done.cross_validated:
            for e in key:
                fixed_hyper.setdefault(e, done.hyper().get(e, {}))

    # Terms the trials did not identify (their fit on the trials alone was unstable on
    # the passes): every model with one of them is identified with the verified passes.
    on_folds: set[str] = set()
    n_verified = sum(p.verified for p in dataset.passes)
    # the evaluations this selection asked for: a cache filled by another rule's run holds
    # others too, which the agreement witness must not see (``fitted_before``)
    used: set[tuple[str, ...]] = set()

    def ev(effects: list[str], parent: Evaluation | None = None, folds: bool = False
           ) -> Evaluation:
        folds = folds or any(e in on_folds for e in effects)
        key = _cache_key(effects, folds)
        used.add(key)
        if key not in cache:
            hyper = {e: dict(fixed_hyper[e]) for e in effects if e in fixed_hyper}
            fold_hyper = ([dict(f.hyper) for f in parent.folds]
                          if parent is not None and parent.cross_validated else None)
            cache[key] = evaluate(dataset, effects, hyper, sigma0, valid_ref, method,
                                  fold_hyper=fold_hyper, folds=folds)
            # A hyper-parameter found on the calibration trials alone (a sensor delay) is
            # kept for the later steps; one found on folds of passes is searched again.
            for e in effects:
                if e not in fixed_hyper and not cache[key].cross_validated:
                    fixed_hyper[e] = cache[key].hyper().get(e, {})
        return cache[key]

    current: list[str] = []
    base = ev(current)
    steps: list[Step] = []

    def fitted_before(c: str) -> list[Evaluation]:
        """``c``'s fits beside the models of the earlier steps, as judged there (on the
        folds where it was refitted so): from this run's fits, no new one."""
        found = []
        for st in steps:
            for folds in (True, False):
                if (key := _cache_key([*st.model, c], folds)) in used:
                    found.append(cache[key])
                    break
        return found

    tried = list(library)
    while len(current) < cfg.max_effects:
        todo = [c for c in tried if c not in current]
        if not todo:
            break
        cur = ev(current)

        def judge(c: str, now: list[str] = current, cur: Evaluation = cur,
                  n_tried: int = len(todo)) -> tuple[Evaluation, CandidateScore]:
            """``c`` added to the current model, scored against it (``_reference``)."""
            cand = ev([*now, c], cur)
            ref = _reference(cfg, cand, cur, lambda: ev(now, folds=True))
            return cand, compare(dataset, ref, cand, c, n_tried, cfg, fitted_before(c))

        scores = []
        for c in todo:
            cand, score = judge(c)
            if score.why.startswith(UNSTABLE_WHY) and not cand.cross_validated \
                    and n_verified >= 2:
                # Identified on the trials alone, it did not fit the passes: the trials
                # (a little swinging, say) did not excite it. It is identified where the
                # data do, with the verified passes, from here on (its trials' hyper-
                # parameters dropped): the swing's term on a friction + swing machine went
                # from 29.7 x the residual to 91 % less (docs/diagnosis.md).
                on_folds.add(c)
                fixed_hyper.pop(c, None)
                cand, score = judge(c)
            scores.append(score)
        scores.sort(key=lambda s: -s.gain if math.isfinite(s.gain) else math.inf)
        chosen = first.name if (first := _first(scores, cfg)) else None
        sig = [s for s in scores if s.significant]
        added = [chosen] if chosen else []
        tried_pairs: list[CandidateScore] = []
        if not sig and len(current) + 2 <= cfg.max_effects:
            pair, tried_pairs = _pair(
                dataset, cur, scores, cfg, len(todo),
                lambda names, folds=False, now=current, parent=cur: ev(
                    [*now, *names], parent, folds))
            if pair is not None:
                added = pair.name.split("+")
                chosen = pair.name
        steps.append(Step(list(current), scores, chosen, tried_pairs))
        if not added:
            break
        current = [*current, *added]
    # A forward step's verdict on its term is already the backward one while the model
    # around it is the same; the earlier models' fits as the forward steps saw them (a
    # backward step's own fits, a reduced model on the folds, are not an earlier model).
    forward = {(frozenset(st.model), st.chosen): next(c for c in st.candidates
                                                      if c.name == st.chosen)
               for st in steps if st.chosen and "+" not in st.chosen}
    before = {c: fitted_before(c) for c in current}
    while cfg.backward and len(current) >= 2:
        step = _backward(dataset, current, cfg, ev, before, forward)
        steps.append(step)
        if step.removed is None:
            break
        current = [e for e in current if e != step.removed]
    return Selection(list(current), steps, base, ev(current), cache)


def _backward(dataset: DataSet, current: list[str], cfg: SelectionConfig,
              ev: Callable[..., Evaluation], before: dict[str, list[Evaluation]],
              forward: dict[tuple[frozenset[str], str], CandidateScore]) -> Step:
    """Each of ``current``'s terms judged beside all the others, as a last step would judge
    it (against the model without it, on the same data: ``_reference``); the least
    significant of those that no longer qualify is the step's ``removed``. The Bonferroni
    family is the model's terms, fewer than a forward step's candidates, so a term stays
    more easily than it came in (stepwise selection's usual asymmetry: no term goes in and
    out by the same margin). A term a forward step added to the model without it keeps
    that step's verdict (``forward``: the last one added is not fitted again); ``before``:
    each term's fits beside the forward steps' models (``_agrees``)."""
    full = ev(current)
    verdicts = []
    for c in current:
        rest = [e for e in current if e != c]
        if (done := forward.get((frozenset(rest), c))) is not None:
            verdicts.append(done)
            continue
        ref = _reference(cfg, full, ev(rest), partial(ev, rest, folds=True))
        verdicts.append(compare(dataset, ref, full, c, len(current), cfg, before[c]))
    out = [v for v in verdicts if not v.significant]
    removed = min(out, key=lambda v: v.t if math.isfinite(v.t) else -math.inf) if out else None
    return Step(list(current), verdicts, None, removed=removed.name if removed else None)
