"""The diagnosis pipeline: data, base model, selection, explanation, payload figures."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shoveld.diagnose.data import DataSet
from shoveld.diagnose.fit import evaluate
from shoveld.diagnose.select import Selection, SelectionConfig, forward_select
from shoveld.model.effects import EFFECT_TERMS
from shoveld.model.model import Model
from shoveld.signals.table import SignalsTable


@dataclass
class Diagnosis:
    dataset: DataSet
    selection: Selection
    timing: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def found(self) -> list[str]:
        return list(self.selection.found)


def diagnose(calib: list[SignalsTable], measured: list[SignalsTable],
             library: list[str] | None = None, cfg: SelectionConfig | None = None,
             method: str = "staged") -> Diagnosis:
    """Run the whole diagnosis (see the package doc)."""
    t0 = time.perf_counter()
    ds = DataSet(list(calib), list(measured))
    if not ds.passes:
        raise ValueError("no dig cycle (dig, lift, swing) found in the measured data")
    base_view = ds.view(Model.from_names([]))
    valid_ref = [f.use for f in base_view.measured]
    t1 = time.perf_counter()
    probe = evaluate(ds, [], {}, np.ones(2), valid_ref, method)
    p0 = probe.folds[0]
    sigma0 = np.array([p0.noise["handle"], p0.noise["crowd"]]) / p0.get("K_H")
    sel = forward_select(ds, list(library or EFFECT_TERMS), sigma0, valid_ref, cfg, method)
    t2 = time.perf_counter()
    d = Diagnosis(ds, sel, {"prepare_s": t1 - t0, "select_s": t2 - t1})
    d.extra["sigma0"] = sigma0
    d.extra["valid_ref"] = valid_ref
    return d


def payload_stats(errors: np.ndarray, rated_kg: float) -> dict[str, Any]:
    if not len(errors):
        return {"passes": 0}
    mean, rms = float(np.mean(errors)), float(np.sqrt(np.mean(errors**2)))
    return {"passes": int(len(errors)), "mean_kg": round(mean, 1), "rms_kg": round(rms, 1),
            "mean_pct_rated": round(100 * mean / rated_kg, 3),
            "rms_pct_rated": round(100 * rms / rated_kg, 3),
            "max_abs_kg": round(float(np.max(np.abs(errors))), 1) if len(errors) else math.nan}
