"""The diagnosis as JSON and as a short human report (Markdown with PNG plots)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from shoveld.diagnose.core import Diagnosis
from shoveld.diagnose.data import RATED_PAYLOAD_KG
from shoveld.diagnose.explain import VARIABLES, binned
from shoveld.model.params import ModelParams, save_params
from shoveld.model.terms import TERMS
from shoveld.words import n_of


def _verified_hint(found: list[str]) -> str:
    """What the re-identification needs besides the trials: a term only swinging or a full
    dipper excites was identified with the verified passes, and ``shoveld calibrate``
    refuses it without them (fitted on trials alone it weighed passes tonnes off)."""
    if any(getattr(TERMS.get(n), "needs_swing", False)
           or getattr(TERMS.get(n), "needs_full_dipper", False) for n in found):
        return " TRIALS --verified TABLES_OF_WEIGHED_PASSES"
    return ""


def _params_json(p: ModelParams) -> dict[str, Any]:
    units = p.model().param_units
    return {n: {"value": float(v), "stderr": float(se), "unit": u}
            for n, v, se, u in zip(p.names, p.values, p.stderr, units, strict=True)}


def _derived(p: ModelParams) -> dict[str, float]:
    out: dict[str, float] = {}
    values = p.as_dict()
    for t in p.model().terms:
        der = getattr(t, "derived", None)
        if der is not None:
            out.update({k: round(float(v), 5) for k, v in der(values).items()})
    return out


def findings(p: ModelParams, found: list[str]) -> dict[str, list[dict[str, Any]]]:
    """Per named cause, the physical values it found, each with its uncertainty."""
    out: dict[str, list[dict[str, Any]]] = {}
    for t in p.model().terms:
        if t.name in found and hasattr(t, "findings"):
            out[t.name] = [{**f, **{k: round(float(f[k]), 5) for k in ("value", "std", "std_fit")}}
                           for f in t.findings(p.names, p.values, p.cov)]
    return out


def finding_text(f: dict[str, Any]) -> str:
    """'load centre of gravity ...: 0.62 +- 0.08 m', and the data's part of the ± where
    a model error is in it (``ExtensionTerm.model_error``)."""
    unit = f" {f['unit']}" if f["unit"] else ""
    text = f"{f['what']}: {f['value']:.3g} ± {f['std']:.2g}{unit}"
    fit = f.get("std_fit", f["std"])
    if f["std"] > 1.01 * fit:
        text += (f" (the data's part ± {fit:.2g}, the model's "
                 f"± {math.sqrt(f['std'] ** 2 - fit**2):.2g})")
    return text


def added(candidate: str, found: list[str]) -> bool:
    """Was this candidate added? A pair tried together ("a+b", ``select._pair``) was when
    both of its terms were."""
    return all(n in found for n in candidate.split("+"))


def removals(steps: list[dict[str, Any]]) -> dict[str, str]:
    """The terms a backward step removed (``select._backward``), each with why, in words."""
    out = {}
    for st in steps:
        if (name := st.get("removed")) is not None:
            c = next(c for c in st["candidates"] if c["name"] == name)
            others = ", ".join(e for e in st["model"] if e != name)
            out[name] = f"removed at the end, beside {others}: {c['why']}"
    return out


def candidate_verdict(c: dict[str, Any], found: list[str],
                      removed: dict[str, str] | None = None) -> str:
    """A ranked candidate's verdict in words: added (and on what), removed at the end
    (``removals``), or why not."""
    if removed and c["name"] in removed:
        return removed[c["name"]]
    if added(c["name"], found):
        return {"payload": "added on the payload (the residual cannot see it)",
                "agreement": "added: the residual cannot see it, its value holds beside the "
                             "earlier models and the payload improves",
                "prediction": "added: its value is the one its physics predicts, and the "
                              "payload improves",
                "delay": "added on its delay: a stream is late well beyond its standard "
                         "deviation, and the payload does not get worse"
                }.get(c.get("witness", ""), "added")
    return str(c["why"] or "significant")


def cause(name: str) -> str:
    cls = TERMS[name]
    return str(getattr(cls, "cause", "") or cls.description)


def as_json(d: Diagnosis) -> dict[str, Any]:
    sel = d.selection
    ds = d.dataset
    first = sel.steps[0].candidates if sel.steps else []
    out: dict[str, Any] = {
        "found": d.found,
        "causes": {n: cause(n) for n in d.found},
        "physical": findings(d.extended_params, d.found),
        "ranked": [c.as_dict() for c in first],
        "steps": [{"model": s.model, "chosen": s.chosen, "removed": s.removed,
                   "candidates": [c.as_dict() for c in s.candidates],
                   "pairs": [c.as_dict() for c in s.pairs]} for s in sel.steps],
    }
    for tag, ev, res in (("base", sel.base, d.base_residuals),
                         ("extended", sel.extended, d.extended_residuals)):
        entry: dict[str, Any] = {
            "effects": ev.effects, "residual_rms": res.rms(),
            "payload": d.payload(tag), "cross_validated": ev.cross_validated}
        if d.engine:
            entry["payload_engine"] = d.payload(tag, "engine")
        if tag == "base":
            entry["params"] = _params_json(ev.folds[0])
        else:
            entry["params"] = _params_json(d.extended_params)
            entry["hyper"] = d.extended_params.hyper
            entry["derived"] = _derived(d.extended_params)
        out[tag] = entry
    b, e = out["base"]["payload"], out["extended"]["payload"]
    if b.get("passes") and e.get("passes"):
        out["gain"] = {"payload_rms_kg": round(b["rms_kg"] - e["rms_kg"], 1),
                       "payload_rms_pct_rated": round(b["rms_pct_rated"] - e["rms_pct_rated"], 3),
                       "rated_kg": RATED_PAYLOAD_KG}
    out["passes"] = []
    for p in ds.passes:
        row: dict[str, Any] = {"pass": p.index, "table": ds.measured[p.table].source,
                               "start_s": round(p.start_s, 2),
                               "verified_kg": None if not p.verified else round(p.payload_kg, 1)}
        for tag, ev in (("base", sel.base), ("extended", sel.extended)):
            v = ev.scores[p.index].payload_kg
            row[f"{tag}_kg"] = None if not math.isfinite(v) else round(v, 1)
            if d.engine and p.verified:
                v = d.engine.get(tag, {}).get(p.index, math.nan)
                row[f"{tag}_engine_kg"] = None if not math.isfinite(v) else round(v, 1)
        out["passes"].append(row)
    out["residuals_against"] = _round(d.against)
    n = sum(len(t) for t in ds.measured)
    rate = ds.measured[0].sample_rate_hz if ds.measured else math.nan
    out["data"] = {"calib_files": [t.source for t in ds.calib],
                   "measured_files": [t.source for t in ds.measured],
                   "measured_samples": n, "measured_hours": round(n / rate / 3600, 4),
                   "passes": len(ds.passes), "verified_passes": len(d.verified)}
    cfg = d.config
    out["method"] = {"alpha": cfg.alpha, "min_gain": cfg.min_gain,
                     "max_effects": cfg.max_effects, "payload_alpha": cfg.payload_alpha,
                     "decisive_gain": (cfg.decisive_gain if math.isfinite(cfg.decisive_gain)
                                       else None),
                     "decisive_worse_alpha": cfg.decisive_worse_alpha,
                     "align_first": cfg.align_first,
                     "delay_z": cfg.delay_z if math.isfinite(cfg.delay_z) else None,
                     "same_data": cfg.same_data,
                     "blind_z": cfg.blind_z if math.isfinite(cfg.blind_z) else None,
                     "agree_se": cfg.agree_se, "backward": cfg.backward,
                     "test": "per-pass held-out loss differences, one-sided t, Bonferroni "
                             "over the candidates of a step"}
    out["timing_s"] = {k: round(v, 3) for k, v in d.timing.items()}
    return _round(out)


def _round(x: Any) -> Any:
    if isinstance(x, float):
        return None if not math.isfinite(x) else round(x, 5)
    if isinstance(x, dict):
        return {k: _round(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_round(v) for v in x]
    return x


# ------------------------------------------------------------------------ the report
def _signature(name: str | None) -> str:
    if name is None:
        return "payload"
    return str(getattr(TERMS[name], "signature", "") or "payload")


def _plot_cause(d: Diagnosis, key: str, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label, unit = VARIABLES[key]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
    for ax, chan, name in ((axes[0], "hoist_a", "hoist"), (axes[1], "crowd_a", "crowd")):
        for tag, res, col in (("base model", d.base_residuals, "C3"),
                              ("extended model", d.extended_residuals, "C0")):
            if tag == "extended model" and not d.found:
                continue
            x, y = res.variables[key], getattr(res, chan)
            ok = np.isfinite(x) & np.isfinite(y)
            if ok.sum() > 2000:
                pick = np.random.default_rng(0).choice(np.flatnonzero(ok), 2000, replace=False)
            else:
                pick = np.flatnonzero(ok)
            ax.plot(x[pick], y[pick], ".", ms=2, alpha=0.15, color=col)
            b = binned(x, y, 10)
            ax.errorbar(b["centres"], b["mean"], yerr=b["se"], fmt="o-", color=col, label=tag)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(f"{label} ({unit})")
        ax.set_ylabel(f"{name} current: measured - model (A)")
        lim = np.nanpercentile(np.abs(getattr(d.base_residuals, chan)), 98)
        if math.isfinite(lim) and lim > 0:
            ax.set_ylim(-1.2 * lim, 1.2 * lim)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_payload(d: Diagnosis, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ver = d.verified
    fig, ax = plt.subplots(figsize=(9, 4))
    idx = [p.index for p in ver]
    for tag, ev, col, mk in (("base", d.selection.base, "C3", "s"),
                             ("extended", d.selection.extended, "C0", "o")):
        if tag == "extended" and not d.found:
            continue
        err = [ev.scores[p.index].payload_kg - p.payload_kg for p in ver]
        ax.plot(idx, err, mk, color=col, label=f"{tag} model (held out)")
        if d.engine:
            eng = [d.engine[tag].get(p.index, math.nan) - p.payload_kg for p in ver]
            ax.plot(idx, eng, mk, mfc="none", color=col, label=f"{tag}, live engine")
    ax.axhline(0, color="k", lw=0.8, label="truck scale")
    ax.set_xlabel("pass")
    ax.set_ylabel("estimate - scale (kg)")
    sec = ax.secondary_yaxis("right", functions=(
        lambda y: 100 * np.asarray(y) / RATED_PAYLOAD_KG,
        lambda p: np.asarray(p) * RATED_PAYLOAD_KG / 100))
    sec.set_ylabel("% of rated load")
    ax.legend(fontsize=8, ncol=2)
    ax.set_title("Payload per verified pass against the scale")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_overview(d: Diagnosis, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in VARIABLES if k != "payload_x_direction"]
    # Three panels a row, each large enough to read its labels on a laptop or on paper.
    cols = 3
    rows = (len(keys) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(15, 3.6 * rows), squeeze=False)
    for ax, key in zip(axes.flat, keys, strict=False):
        label, unit = VARIABLES[key]
        for chan, col in (("hoist_a", "C3"), ("crowd_a", "C2")):
            b = binned(d.base_residuals.variables[key], getattr(d.base_residuals, chan))
            ax.errorbar(b["centres"], b["mean"], yerr=b["se"], fmt=".-", color=col,
                        label=f"{chan[:5]} ({100 * b['explained']:.0f} %)")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(f"{label} ({unit})", fontsize=12)
        ax.set_ylabel("residual (A)", fontsize=12)
        ax.tick_params(labelsize=11)
        ax.legend(fontsize=10)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    fig.suptitle("Base model: residual current (A, bin means; % = variance explained) "
                 "against each candidate variable", fontsize=14)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_report(d: Diagnosis, out_dir: str | Path) -> Path:
    """Write report.md, the plots and the extended model's params file into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js = as_json(d)
    top = d.found[0] if d.found else (js["ranked"][0]["name"] if js["ranked"] else None)
    key = _signature(top)
    _plot_cause(d, key, out / "residual_vs_cause.png",
                f"Residual against {VARIABLES[key][0]}: "
                + (f"before and after adding {top}" if d.found else "base model"))
    _plot_payload(d, out / "payload_per_pass.png")
    _plot_overview(d, out / "residuals_overview.png")
    save_params(out / "extended.params.toml", d.extended_params)
    b, e = js["base"]["payload"], js["extended"]["payload"]
    lines = ["# Model diagnosis", ""]
    files = ", ".join(js["data"]["measured_files"])
    lines.append(f"Measured data: {files} ({js['data']['measured_hours']:.2f} h, "
                 f"{n_of(js['data']['passes'], 'pass', 'passes')}, "
                 f"{js['data']['verified_passes']} with a scale weight). "
                 f"Calibration trials: {', '.join(js['data']['calib_files'])}.")
    lines += ["", "## Finding", ""]
    if d.found:
        for i, n in enumerate(d.found, 1):
            lines.append(f"{i}. **{cause(n)}** (model term `{n}`).")
            for f in js["physical"].get(n, []):
                lines.append(f"   - {finding_text(f)}")
        lines.append("")
        lines.append(
            f"With {'this' if len(d.found) == 1 else 'these'} in the model, the payload error "
            f"on the {n_of(e.get('passes', 0), 'verified pass', 'verified passes')} "
            "the model had not seen goes from "
            f"{b.get('rms_kg', math.nan):.0f} kg RMS ({b.get('rms_pct_rated', math.nan):.2f} % "
            f"of the {RATED_PAYLOAD_KG:,.0f} kg rated load; "
            f"mean {b.get('mean_kg', math.nan):+.0f} kg)"
            f" to {e.get('rms_kg', math.nan):.0f} kg RMS ({e.get('rms_pct_rated', math.nan):.2f} "
            f"%; mean {e.get('mean_kg', math.nan):+.0f} kg).")
        if d.engine:
            be, ee = js["base"]["payload_engine"], js["extended"]["payload_engine"]
            lines.append(f"The live engine on the same passes: {be.get('rms_kg', math.nan):.0f}"
                         f" kg -> {ee.get('rms_kg', math.nan):.0f} kg RMS.")
    else:
        lines.append("**Nothing significant.** No candidate extension removed enough of the "
                     "model's error on passes it had not seen to count as a finding; the base "
                     "model's payload error on the verified passes is "
                     f"{b.get('rms_kg', math.nan):.0f} kg RMS "
                     f"({b.get('rms_pct_rated', math.nan):.2f} % of rated load).")
    lines += ["", "## What the base model gets wrong", "",
              "Measured minus model current, per channel, over the lift and swing of every pass "
              f"(hoist {js['base']['residual_rms']['hoist_A']:.1f} A RMS, crowd "
              f"{js['base']['residual_rms']['crowd_A']:.1f} A RMS; with the extension "
              f"{js['extended']['residual_rms']['hoist_A']:.1f} A and "
              f"{js['extended']['residual_rms']['crowd_A']:.1f} A).", "",
              "![residual against the cause](residual_vs_cause.png)", "",
              "Against every variable that a physical cause would make it follow (the "
              "percentage is the share of the residual variance the bins explain):", "",
              "![residuals against each variable](residuals_overview.png)", ""]
    delay = js["residuals_against"]["time_shift"].get("implied_delay_s", {}).get("base")
    if delay is not None:
        lines.append(f"A time shift of {1000 * delay:+.0f} ms between current and motion would "
                     "explain the hoist residual to first order.")
    lines += ["", "## Candidates (first step)", "",
              "| candidate | residual removed | t (critical) | held-out payload RMS | verdict |",
              "|---|---|---|---|---|"]
    pairs = js["steps"][0]["pairs"] if js["steps"] else []
    gone = removals(js["steps"])
    for c in js["ranked"] + pairs:
        verdict = candidate_verdict(c, d.found, gone)
        if added(c["name"], d.found):
            verdict = f"**{verdict}**"
        score = 100 * (c["score"] or 0)
        removed = f"{score:+.1f} %" if abs(score) < 1000 else "unstable"
        lines.append(f"| `{c['name']}` | {removed} | "
                     f"{c['t'] if c['t'] is not None else 'n/a'} ({c['t_crit']}) | "
                     f"{c['payload_rms_kg']} kg | {verdict} |")
    lines += ["", "## Payload per pass", "", "![payload per pass](payload_per_pass.png)", "",
              "## The extended model", "",
              f"Terms: {', '.join(d.extended_params.terms)}. Written to "
              "`extended.params.toml` (load it with `shoveld estimate --params` or the "
              "daemon; or re-identify with `shoveld calibrate --effects "
              f"{','.join(d.found) or '...'}{_verified_hint(d.found)}`).", "",
              "| parameter | value | std err | unit |", "|---|---|---|---|"]
    for n, v in js["extended"]["params"].items():
        lines.append(f"| {n} | {v['value']:.6g} | {v['stderr']:.3g} | {v['unit']} |")
    for term, h in d.extended_params.hyper.items():
        if term in d.found and h:
            lines.append(f"| {term} (hyper) | {h} | | |")
    for k, v in js["extended"]["derived"].items():
        lines.append(f"| {k} | {v:.4g} | | |")
    # The masking the terms declare (``ExtensionTerm.masked_by``), in words.
    masked = [f"{TERMS[n].description} beside {TERMS[m].description}"
              for n, t in TERMS.items() for m in getattr(t, "masked_by", ())]
    lines += ["", "## Method", "",
              "Each candidate is added on its own to the current model, identified by the same "
              "calibration as the base model (on the calibration trials; with cross-validation "
              "over verified passes when only operating data excites it), and judged pass by "
              "pass on data it was not fitted on. A candidate is added when the per-pass "
              f"improvement is significant (one-sided t, family-wise alpha {d.config.alpha} per "
              f"step), removes at least {100 * d.config.min_gain:.0f} % of the held-out residual, "
              "and cuts the verified passes' payload errors significantly"
              + (f" (or, where it removes at least {100 * d.config.decisive_gain:.0f} % of the "
                 "residual, "
                 + (f"does not make them significantly worse: one-sided, alpha "
                    f"{d.config.decisive_worse_alpha})" if d.config.decisive_worse_alpha < 1.0
                    else "does not raise their payload RMS)")
                 if math.isfinite(d.config.decisive_gain) else "")
              + ("; a candidate identified with the verified passes is judged against the "
                 "current model identified on the same passes" if d.config.same_data else "")
              + (f". A term the residual cannot see (the rope's weight, which the dipper's "
                 "mass absorbs) is added on the payload alone when each of its parameters "
                 f"stands {d.config.blind_z:g} standard errors from zero on its physical side "
                 "and the verified passes' payload errors fall"
                 + (", or their RMS falls and its value agrees, within "
                    f"{d.config.agree_se:g} standard errors, with its value beside each "
                    "model of the earlier steps (a term standing in for another cause "
                    "moves as the model around it changes)" if d.config.agree_se > 0 else "")
                 + (f"; a term masked by one in the model ({'; '.join(masked)}: the two "
                    "look alike to the residual) is judged the same way, on the payload "
                    "whatever its share of the residual" if masked else "")
                 if math.isfinite(d.config.blind_z) else "")
              + (". Of those that qualify at a step, a re-alignment of the sensor streams "
                 "in time that removes a decisive share of the residual is added first (the "
                 "other terms fitted on streams out of step take part of the lag into their "
                 "own shape), then one whose value is the one its physics predicts, else the "
                 "largest share" if d.config.align_first and math.isfinite(
                     d.config.decisive_gain) else "")
              + (". A re-alignment significant on the residual that the payload tests cannot "
                 "judge (a stream's lateness moves the payload little) is added when a "
                 f"device is late by {d.config.delay_z:g} standard deviations or more and "
                 "the payload does not get worse" if math.isfinite(d.config.delay_z) else "")
              + ". The search repeats until none qualifies"
              + ("; then each term found is judged again beside all the others, as if it "
                 "came last, and one that no longer qualifies is removed" if d.config.backward
                 else "") + "."]
    (out / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out / "report.md"
