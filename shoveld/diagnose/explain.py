"""The disagreement, shown: residual currents per channel against what could explain them.

For every lift and swing sample of the measured passes the model predicts the hoist
current (from the handle equation) and the crowd current (from the crowd equation,
given the measured hoist current) for the measured motion and the known payload
(the scale's where verified, the pass's own estimate otherwise). The residual
current, measured minus predicted, in amperes per channel, is binned against each
variable that a physical cause would make it follow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from shoveld.diagnose.data import DataSet
from shoveld.diagnose.fit import Evaluation, as_measured, current_residuals

VARIABLES: dict[str, tuple[str, str]] = {
    "hoist_field_a": ("hoist field current", "A"),
    "swing_rate": ("swing speed", "deg/s"),
    "handle_angle": ("handle angle", "deg"),
    "crowd_length": ("crowd extension", "m"),
    "rope_length": ("hoist rope length, sheave to bail", "m"),
    "payload": ("payload", "kg"),
    "hoist_current": ("hoist current", "A"),
    "payload_x_direction": ("payload x direction of handle motion", "kg"),
    "pitch": ("machine pitch (cab inclinometer)", "deg"),
    "roll": ("machine roll (cab inclinometer)", "deg"),
    "time_shift": ("rate of change of the hoist current", "A/s"),
}
"""Residuals are binned against these (key: label, unit)."""


@dataclass
class Residuals:
    """Per-sample residual currents and the explaining variables, all passes."""

    hoist_a: np.ndarray
    crowd_a: np.ndarray
    handle_nm: np.ndarray
    crowd_n: np.ndarray
    pass_index: np.ndarray
    variables: dict[str, np.ndarray]

    def rms(self) -> dict[str, float]:
        def r(x: np.ndarray) -> float:
            x = x[np.isfinite(x)]
            return round(float(np.sqrt(np.mean(x * x))), 4) if len(x) else math.nan
        return {"hoist_A": r(self.hoist_a), "crowd_A": r(self.crowd_a),
                "handle_Nm": r(self.handle_nm), "crowd_N": r(self.crowd_n)}


def residuals(dataset: DataSet, ev: Evaluation, valid_ref: list[np.ndarray]) -> Residuals:
    """Residual currents of ``ev``'s held-out models over every pass."""
    out: dict[str, list[np.ndarray]] = {k: [] for k in (
        "hoist_a", "crowd_a", "handle_nm", "crowd_n", "pass", *VARIABLES)}
    for p in dataset.passes:
        params = ev.folds[ev.fold_of[p.index]]
        model = params.model()
        f = dataset.view(model).measured[p.table]
        idx = p.eval_idx[valid_ref[p.table][p.eval_idx] & f.use[p.eval_idx]]
        if len(idx) < 10:
            continue
        k = as_measured(f.kin.take(idx))
        m = p.payload_kg if p.verified else ev.scores[p.index].payload_kg
        e = model.residual(k, params.values, m)
        r = current_residuals(model, k, params.values, m)
        out["hoist_a"].append(r[:, 0])
        out["crowd_a"].append(r[:, 1])
        out["handle_nm"].append(e[:, 0])
        out["crowd_n"].append(e[:, 1])
        out["pass"].append(np.full(len(idx), p.index))
        t = k.t
        assert k.i_h_est is not None  # Kinematics.__post_init__ sets it
        di = np.gradient(k.i_h_est, t) if len(t) > 2 else np.zeros(len(t))
        v = {
            "hoist_field_a": k.i_hf, "swing_rate": np.degrees(np.abs(k.swing_rate)),
            "handle_angle": np.degrees(k.th), "crowd_length": k.d, "rope_length": k.l_sd,
            "payload": np.full(len(idx), m), "hoist_current": k.i_h,
            "payload_x_direction": m * np.sign(k.thd), "pitch": np.degrees(k.pitch),
            "roll": np.degrees(k.roll), "time_shift": di}
        for key, val in v.items():
            out[key].append(np.asarray(val, dtype=float))
    cat = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in out.items()}
    return Residuals(cat["hoist_a"], cat["crowd_a"], cat["handle_nm"], cat["crowd_n"],
                     cat["pass"], {k: cat[k] for k in VARIABLES})


def binned(x: np.ndarray, y: np.ndarray, bins: int = 8) -> dict[str, Any]:
    """Quantile bins of x: centres, mean and standard error of y, and the share of y's
    variance the bin means explain (eta squared)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 4 * bins or np.ptp(x) <= 0:
        return {"centres": [], "mean": [], "se": [], "count": [], "explained": 0.0}
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    centres, means, ses, counts = [], [], [], []
    between = 0.0
    total = float(np.sum((y - y.mean()) ** 2))
    for j in range(len(edges) - 1):
        s = which == j
        if s.sum() < 2:
            continue
        centres.append(float(np.median(x[s])))
        means.append(float(y[s].mean()))
        ses.append(float(y[s].std(ddof=1) / math.sqrt(s.sum())))
        counts.append(int(s.sum()))
        between += float(s.sum() * (y[s].mean() - y.mean()) ** 2)
    return {"centres": centres, "mean": means, "se": ses, "count": counts,
            "explained": between / total if total > 0 else 0.0}


def implied_delay_s(r: Residuals) -> float:
    """The time shift that would explain the hoist residual to first order: the slope
    of the residual current on the rate of change of the current (seconds)."""
    x, y = r.variables["time_shift"], r.hoist_a
    ok = np.isfinite(x) & np.isfinite(y)
    den = float(np.sum(x[ok] ** 2))
    return float(np.sum(x[ok] * y[ok]) / den) if den > 0 else 0.0


def against(base: Residuals, ext: Residuals | None) -> dict[str, Any]:
    """Binned residuals of both models against every variable."""
    out: dict[str, Any] = {}
    for key, (label, unit) in VARIABLES.items():
        entry: dict[str, Any] = {"label": label, "unit": unit}
        for tag, r in (("base", base), ("extended", ext)):
            if r is None:
                continue
            entry[tag] = {"hoist_A": binned(r.variables[key], r.hoist_a),
                          "crowd_A": binned(r.variables[key], r.crowd_a)}
        out[key] = entry
    out["time_shift"]["implied_delay_s"] = {"base": round(implied_delay_s(base), 4)}
    if ext is not None:
        out["time_shift"]["implied_delay_s"]["extended"] = round(implied_delay_s(ext), 4)
    return out
