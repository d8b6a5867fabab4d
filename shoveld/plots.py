"""Plots for the field engineer: calibration fit and per-pass payload.

matplotlib is an optional dependency (extra ``plots``); it is imported here only,
with the Agg backend, so a headless shovel computer never needs a display.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shoveld.cycle.phases import PHASES
from shoveld.words import n_of


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise RuntimeError("plots need matplotlib: pip install 'shoveld[plots]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # legible on a laptop screen and on paper
    plt.rcParams.update({"font.size": 12, "axes.titlesize": 13, "axes.labelsize": 12,
                         "legend.fontsize": 11, "xtick.labelsize": 11, "ytick.labelsize": 11})
    return plt


def plot_calibration(cal: Any, out_dir: str | Path) -> list[Path]:
    """Per calibration file: measured hoist and crowd effort against the identified model,
    with the excluded samples shaded, and the residuals. Returns the PNG paths."""
    plt = _pyplot()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    p = cal.params_.values
    names = cal.model.param_names
    kh = p[names.index("K_H")]
    paths = []
    for k, f in enumerate(cal.files_):
        good = np.isfinite(f.kin.th) & np.isfinite(f.payload)
        kin = f.kin.take(good)
        output = getattr(cal, "method", "output") == "output"
        if output:
            # What output error fits: measured minus predicted current, per channel (A).
            from shoveld.model.output import CurrentEquations

            res = CurrentEquations(cal.model, kin).residual(p, f.payload[good])
        else:
            w, phi, psi = cal.model.regressor(kin)
            m = f.payload[good][:, None]
            res = (w @ p + m * (phi + psi @ p)) / 1e3  # kN m, kN
        t = kin.t
        use = f.use[good]
        fig, ax = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
        ax[0].plot(t, np.degrees(kin.th), lw=0.8, color="C0")
        ax[0].set_ylabel("handle angle (deg)", color="C0")
        crowd_ax = ax[0].twinx()  # one unit per axis
        crowd_ax.plot(t, kin.d, lw=0.8, color="C1")
        crowd_ax.set_ylabel("crowd extension (m)", color="C1")
        for a in ax:
            a.fill_between(t, 0, 1, where=~use, transform=a.get_xaxis_transform(),
                           color="0.85", lw=0, label="excluded" if a is ax[1] else None)
        # The residual is drawn only where the model was fitted: an excluded span (digging,
        # a saturated sensor) shows as a shaded gap, not as a misfit.
        shown = np.where(use[:, None], res, np.nan)
        ax[1].plot(t, shown[:, 0], lw=0.6, color="C3")
        ax[1].set_ylabel("hoist current residual (A)" if output else "handle residual (kN m)")
        ax[1].axhline(0, color="k", lw=0.5)
        ax[1].legend(loc="upper right")
        ax[2].plot(t, shown[:, 1], lw=0.6, color="C2")
        ax[2].set_ylabel("crowd current residual (A)" if output else "crowd residual (kN)")
        ax[2].axhline(0, color="k", lw=0.5)
        ax[2].set_xlabel("time (s)")
        rms = np.sqrt(np.mean(res[use] ** 2, axis=0))
        if output:
            fig.suptitle(f"{f.name}: residual RMS over the fitted samples: hoist {rms[0]:.1f} A, "
                         f"crowd {rms[1]:.1f} A; K_H {kh:.0f} N per A", fontsize=12)
        else:
            eq_kg = rms[0] * 1e3 / (9.81 * np.mean(kin.d[use]))
            fig.suptitle(f"{f.name}: residual RMS handle {rms[0]:.1f} kN m (about "
                         f"{eq_kg:.0f} kg at the bail), crowd {rms[1]:.1f} kN; "
                         f"K_H {kh:.0f} N per A", fontsize=12)
        path = out_dir / f"calibration-{k + 1}-{Path(f.name).stem}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def plot_estimate(table: Any, est: Any, path: str | Path) -> Path:
    """Handle angle with phases, the live payload with its 2-sigma band, and each pass."""
    plt = _pyplot()
    live = est.live
    t = np.array([x.time_s for x in live])
    pay = np.array([x.payload_kg for x in live]) / 1000
    std = np.array([x.std_kg for x in live]) / 1000
    ph = np.array([PHASES.index(x.phase) for x in live])
    fig, ax = plt.subplots(2, 1, figsize=(12, 7), sharex=True)
    ax[0].plot(table.time, table["handle_deg"], lw=0.7, color="k")
    ax[0].set_ylabel("handle angle (deg)")
    colors = ["white", "#f4c7a1", "#b7d7f0", "#c9e7c1", "#f0b7b7", "#e3e3e3"]
    for k, name in enumerate(PHASES):
        if k:
            ax[0].fill_between(t, 0, 1, where=ph == k, transform=ax[0].get_xaxis_transform(),
                               color=colors[k], lw=0, label=name)
    ax[0].legend(loc="upper right", ncol=5)
    ax[1].plot(t, pay, lw=0.8, label="live estimate")
    ax[1].fill_between(t, pay - 2 * std, pay + 2 * std, alpha=0.25, lw=0, label="±2σ")
    for p in est.passes:
        if p.valid:
            ax[1].errorbar([p.end_s], [p.payload_kg / 1000], yerr=[2 * p.std_kg / 1000], fmt="o",
                           color="C3", ms=4)
            ax[1].annotate(f"{p.payload_kg / 1000:.1f} t", (p.end_s, p.payload_kg / 1000),
                           textcoords="offset points", xytext=(3, 6), fontsize=10)
    truth = table["payload_kg"]
    if np.isfinite(truth).any():
        ax[1].plot(table.time, truth / 1000, ".", ms=1, color="k", label="scale")
    ax[1].set_ylabel("payload (t)")
    ax[1].set_xlabel("time (s)")
    ax[1].set_ylim(-3, 45)
    ax[1].legend(loc="upper right")
    fig.suptitle(f"{table.source}: {n_of(len(est.passes), 'pass', 'passes')}", fontsize=12)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
