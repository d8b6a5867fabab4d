"""The diagnosis pipeline: data, base model, selection, explanation, payload figures."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shoveld.diagnose.data import RATED_PAYLOAD_KG, DataSet, Pass
from shoveld.diagnose.explain import Residuals, against, residuals
from shoveld.diagnose.fit import Evaluation, evaluate, fit
from shoveld.diagnose.select import Selection, SelectionConfig, forward_select
from shoveld.model.effects import EFFECT_TERMS
from shoveld.model.model import Model
from shoveld.model.params import ModelParams
from shoveld.model.terms import TERMS
from shoveld.signals.table import SignalsTable

MODELLED_BY_BASE: dict[str, str] = {"hoist_field_weakening": "hoist_drive"}
"""Simulated effects the base model itself carries, and the term that does: the right
diagnosis of data with one of them names nothing."""


@dataclass
class Diagnosis:
    """Everything ``shoveld diagnose`` reports (``as_json``) and plots (``report``)."""

    dataset: DataSet
    selection: Selection
    base_residuals: Residuals
    extended_residuals: Residuals
    extended_params: ModelParams
    """The extended model fitted on all the data it may use: the params file to deploy."""
    against: dict[str, Any] = field(default_factory=dict)
    """Binned residuals against every explaining variable (``explain.against``)."""
    engine: dict[str, dict[int, float]] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    config: SelectionConfig = field(default_factory=SelectionConfig)

    @property
    def found(self) -> list[str]:
        return list(self.selection.found)

    @property
    def verified(self) -> list[Pass]:
        return [p for p in self.dataset.passes if p.verified]

    def payload(self, which: str, source: str = "offline") -> dict[str, Any]:
        ev = self.selection.base if which == "base" else self.selection.extended
        if source == "engine":
            est = self.engine.get(which, {})
            errs = np.array([est[p.index] - p.payload_kg for p in self.verified
                             if math.isfinite(est.get(p.index, math.nan))])
            out = payload_stats(errs)
            out["missed"] = sum(1 for p in self.verified
                                if not math.isfinite(est.get(p.index, math.nan)))
            return out
        return payload_stats(ev.payload_errors(self.dataset.passes))

    def as_json(self) -> dict[str, Any]:
        from shoveld.diagnose.report import as_json

        return as_json(self)


def payload_stats(errors: np.ndarray) -> dict[str, Any]:
    """Mean and RMS payload error in kg and % of the rated load."""
    errors = np.asarray(errors, dtype=float)
    errors = errors[np.isfinite(errors)]
    if not len(errors):
        return {"passes": 0}
    mean, rms = float(np.mean(errors)), float(np.sqrt(np.mean(errors**2)))
    return {"passes": int(len(errors)), "mean_kg": round(mean, 1), "rms_kg": round(rms, 1),
            "mean_pct_rated": round(100 * mean / RATED_PAYLOAD_KG, 3),
            "rms_pct_rated": round(100 * rms / RATED_PAYLOAD_KG, 3),
            "max_abs_kg": round(float(np.max(np.abs(errors))), 1)}


def engine_payloads(dataset: DataSet, ev: Evaluation) -> dict[int, float]:
    """The live engine's final payload of every verified pass, each run by the fold model
    that did not see it (the table is cut to the pass, with a few seconds before it)."""
    from shoveld.engine.offline import estimate_table

    out: dict[int, float] = {}
    for p in dataset.passes:
        if not p.verified:
            continue
        table = dataset.measured[p.table]
        t = table.time
        cut = table.slice((t >= p.start_s - 4.0) & (t <= p.end_s + 0.5))
        est = estimate_table(cut, ev.folds[ev.fold_of[p.index]])
        near = [r for r in est.passes if abs(r.start_s - p.start_s) < 3.0 and r.valid]
        out[p.index] = near[0].payload_kg if near else math.nan
    return out


def diagnose(calib: list[SignalsTable], measured: list[SignalsTable],
             library: list[str] | None = None, cfg: SelectionConfig | None = None,
             method: str = "output", engine: bool = True,
             cache: dict[tuple[str, ...], Evaluation] | None = None) -> Diagnosis:
    """Run the whole diagnosis (see the package doc). ``cache``: as ``forward_select``'s
    (evaluations of a former run on the same data)."""
    cfg = cfg or SelectionConfig()
    library = list(library or EFFECT_TERMS)
    unknown = [n for n in library if n not in TERMS]
    if unknown:
        raise ValueError(f"unknown model term(s) {unknown}; known: {sorted(TERMS)}")
    t0 = time.perf_counter()
    ds = DataSet(list(calib), list(measured))
    if not ds.passes:
        raise ValueError("no dig cycle (dig, lift, swing) found in the measured data")
    valid_ref = [f.use for f in ds.view(Model.from_names([])).measured]
    t1 = time.perf_counter()
    # The base model's current residual on the measured passes (A, per channel) is the
    # common unit of all losses, so both channels weigh alike.
    probe = residuals(ds, evaluate(ds, [], {}, np.ones(2), valid_ref, method), valid_ref)
    sigma0 = np.array([probe.rms()["hoist_A"], probe.rms()["crowd_A"]])
    sel = forward_select(ds, library, sigma0, valid_ref, cfg, method, cache)
    t2 = time.perf_counter()
    ext = sel.extended
    train = {p.index for p in ds.passes if p.verified} if ext.cross_validated else None
    final = fit(ds, sel.found, ext.hyper() if not ext.cross_validated else {}, train, method)
    base_r = residuals(ds, sel.base, valid_ref)
    ext_r = residuals(ds, ext, valid_ref)
    t3 = time.perf_counter()
    d = Diagnosis(ds, sel, base_r, ext_r, final, config=cfg,
                  against=against(base_r, ext_r if sel.found else None))
    if engine:
        d.engine["base"] = engine_payloads(ds, sel.base)
        d.engine["extended"] = (d.engine["base"] if not sel.found
                                else engine_payloads(ds, ext))
    t4 = time.perf_counter()
    d.timing = {"prepare_s": t1 - t0, "select_s": t2 - t1, "explain_s": t3 - t2,
                "engine_s": t4 - t3, "total_s": t4 - t0}
    return d
