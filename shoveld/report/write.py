"""The shift report on disk: ``index.html`` (one file, plots inside it, opens in any
browser with no other software), the same plots as PNG, and the tables as CSV."""

from __future__ import annotations

import base64
import csv
import datetime as dt
import html
import io
from pathlib import Path
from typing import Any

from shoveld.payload.misfit import MISFIT_WARN
from shoveld.report.figures import ShiftFigures
from shoveld.words import n_of


def _when(t: float) -> str:
    return dt.datetime.fromtimestamp(t).astimezone().strftime("%Y-%m-%d %H:%M")


def _plots(f: ShiftFigures) -> dict[str, bytes]:
    """PNG bytes of each plot (matplotlib, Agg), legible on a printed page."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 13, "axes.titlesize": 15, "axes.labelsize": 13})
    out: dict[str, bytes] = {}

    def save(name: str, fig: Any) -> None:
        buf = io.BytesIO()
        fig.tight_layout()
        fig.savefig(buf, format="png", dpi=110)
        plt.close(fig)
        out[name] = buf.getvalue()

    if f.hours:
        fig, ax = plt.subplots(figsize=(8, 3.6))
        labels = [dt.datetime.fromtimestamp(h).astimezone().strftime("%H:00") for h, _, _ in
                  f.hours]
        ax.bar(range(len(f.hours)), [t for _, t, _ in f.hours], color="#2b6cb0")
        ax.set_xticks(range(len(f.hours)), labels, rotation=45 if len(labels) > 8 else 0)
        ax.set_xlabel("hour (local time)")
        ax.set_ylabel("tonnes loaded (t)")
        ax.set_title("Tonnes per hour")
        save("tonnes_per_hour", fig)
    if f.valid_kg:
        fig, ax = plt.subplots(figsize=(6, 3.6))
        ax.hist([k / 1000 for k in f.valid_kg], bins=20, color="#2b6cb0")
        ax.set_xlabel("pass payload (t)")
        ax.set_ylabel("passes")
        ax.set_title("Pass payloads")
        save("pass_payloads", fig)
    # a truck with a pass not weighed has a fill known only from below: left out
    fills = [t["fill_pct"] for t in f.trucks if t["closed"] and not t["invalid_passes"]]
    short = sum(1 for t in f.trucks if t["closed"] and t["invalid_passes"])
    if fills:
        fig, ax = plt.subplots(figsize=(6, 3.6))
        ax.hist(fills, bins=15, color="#2b6cb0")
        for x, c in ((100, "black"), (110, "#b35900"), (120, "#c40000")):
            ax.axvline(x, color=c, linestyle="--", linewidth=1.5)
        ax.set_xlabel("truck fill (% of target)")
        ax.set_ylabel("trucks")
        ax.set_title("Truck fill (closed trucks" + (
            f"; {n_of(short, 'truck', 'trucks')} with a pass not weighed left out)"
            if short else ")"))
        save("truck_fill", fig)
    if f.empties:
        fig, ax = plt.subplots(figsize=(8, 3.6))
        when = [dt.datetime.fromtimestamp(e["end"]).astimezone() for e in f.empties]
        ax.errorbar(when,  # type: ignore[arg-type]  # datetimes: matplotlib's stubs lack them
                    [e["payload_kg"] for e in f.empties],
                    yerr=[e["std_kg"] for e in f.empties], fmt="o", markersize=3,
                    color="#2b6cb0", ecolor="#9bb8d8", label="each return")
        ax.plot(when,  # type: ignore[arg-type]  # datetimes: matplotlib's stubs lack them
                [e["median_kg"] for e in f.empties], color="black",
                label="median of the last returns")
        warn = max(e["warn_kg"] for e in f.empties)
        for y in (warn, -warn):
            ax.axhline(y, color="#c40000", linestyle="--", linewidth=1.5)
        ax.axhline(0.0, color="#888888", linewidth=0.8)
        ax.set_ylabel("empty dipper (kg)")
        ax.set_title(f"The empty dipper on the returns (level ±{warn:.0f} kg)")
        ax.legend(loc="best", fontsize=10)
        from matplotlib.dates import DateFormatter

        ax.xaxis.set_major_formatter(DateFormatter("%H:%M", tz=when[0].tzinfo))
        ax.set_xlabel("end of the return (local time)")
        fig.autofmt_xdate()
        save("empty_dipper", fig)
    if f.cycle_s:
        fig, ax = plt.subplots(figsize=(6, 3.6))
        ax.hist(f.cycle_s, bins=20, color="#2b6cb0")
        ax.set_xlabel("cycle time, dump to dump (s)")
        ax.set_ylabel("cycles")
        ax.set_title("Cycle times")
        save("cycle_times", fig)
    return out


def write_csv(f: ShiftFigures, out: Path) -> None:
    with open(out / "passes.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["pass", "truck", "shovel", "start", "end", "payload_kg", "std_kg", "valid",
                    "reason", "misfit"])
        for p in f.passes:
            m = p.get("misfit")
            w.writerow([p["pass"], p["truck"], p["shovel"], _when(p["start"]), _when(p["end"]),
                        "" if p["payload_kg"] is None else f"{p['payload_kg']:.1f}",
                        "" if p["std_kg"] is None else f"{p['std_kg']:.1f}", int(p["valid"]),
                        p["reason"], "" if m is None else f"{m:.2f}"])
    with open(out / "trucks.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["truck", "passes", "invalid_passes", "total_kg", "target_kg", "fill_pct",
                    "status", "closed"])
        for t in f.trucks:
            w.writerow([t["truck"], t["passes"], t["invalid_passes"], f"{t['total_kg']:.1f}",
                        f"{t['target_kg']:.1f}", t["fill_pct"], t["status"], int(t["closed"])])
    if f.empties is not None:
        with open(out / "empties.csv", "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["after_pass", "shovel", "end", "empty_kg", "std_kg", "samples",
                        "median_kg", "beyond", "warn_kg"])
            for e in f.empties:
                w.writerow([e["after_pass"], e["shovel"], _when(e["end"]),
                            f"{e['payload_kg']:.1f}", f"{e['std_kg']:.1f}", e["samples"],
                            f"{e['median_kg']:.1f}", int(e["beyond"]), f"{e['warn_kg']:.0f}"])
    with open(out / "hours.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["hour", "tonnes", "passes"])
        for h, tonnes, n in f.hours:
            w.writerow([_when(h), f"{tonnes:.2f}", n])


def write_report(f: ShiftFigures, out: Path, title: str = "Shift report") -> Path:
    """Write the report into ``out`` (created); returns the HTML file."""
    out.mkdir(parents=True, exist_ok=True)
    write_csv(f, out)
    plots = _plots(f)
    for name, png in plots.items():
        (out / f"{name}.png").write_bytes(png)
    e = html.escape
    r = f.rule
    valid = f.valid_kg
    lines = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{e(title)}</title><style>",
        "body{font:16px/1.4 'DejaVu Sans',Arial,sans-serif;margin:2rem;max-width:70rem}",
        "table{border-collapse:collapse;margin:.5rem 0 1.5rem}",
        "td,th{border-bottom:1px solid #ccc;padding:.2rem .6rem;text-align:right}",
        "td:first-child,th:first-child{text-align:left}.bad{color:#c40000}",
        "img{max-width:100%;margin:.5rem 1rem .5rem 0}",
        "</style></head><body>",
        f"<h1>{e(title)}</h1>",
        f"<p>{_when(f.since)} to {_when(f.until)} &middot; "
        f"{n_of(len(f.passes), 'pass', 'passes')} ({len(f.invalid)} not weighed) &middot; "
        f"{n_of(len(f.trucks), 'truck', 'trucks')} &middot; "
        f"<b id='total'>{f.total_kg / 1000:.1f} t</b> loaded"
        + (f" &middot; mean pass {sum(valid) / len(valid) / 1000:.1f} t" if valid else "")
        + "</p>",
        "<h2>10/10/20 rule (closed trucks)</h2>",
    ]
    nj = int(r.get("not_judged") or 0)
    skipped = (f" {n_of(nj, 'truck', 'trucks')} with a pass not weighed "
               f"{'was' if nj == 1 else 'were'} not judged: their loads are known only "
               "from below." if nj else "")
    if r.get("trucks"):
        lines.append(
            f"<p id='rule'>{n_of(r['trucks'], 'truck', 'trucks')}, "
            f"mean {r['mean_kg'] / 1000:.1f} t = "
            f"{r['mean_pct']} % of target; {r['over_110_pct']} % over 110 % (at most 10 % "
            f"allowed); {r['over_120']} over 120 % (none allowed): <b"
            + ("" if r["compliant"] else " class='bad'") + ">"
            + ("within the rule" if r["compliant"] else "OUTSIDE the rule") + "</b>."
            + (" Trucks are being sent under-loaded (mean below 90 %)."
               if r["mean_pct"] < 90 else "") + e(skipped) + "</p>")
    elif nj:
        over = (f" {r['over_120']} over 120 % by their weighed passes alone: "
                "<b class='bad'>OUTSIDE the rule</b>." if r.get("over_120") else "")
        lines.append(f"<p id='rule'>No truck judged.{e(skipped)}{over}</p>")
    else:
        lines.append("<p>No truck was closed in this period.</p>")
    lines += ["<h2>Trucks</h2><table id='trucks'><tr><th>truck</th><th>passes</th>"
              "<th>loaded (t)</th><th>target (t)</th><th>fill</th><th>status</th></tr>"]
    for t in f.trucks:
        cls = " class='bad'" if t["status"].startswith("over") else ""
        nw = int(t.get("invalid_passes") or 0)
        lines.append(f"<tr{cls}><td>{t['truck']}</td><td>{t['passes']}"
                     + (f" ({nw} not weighed)" if nw else "") + "</td>"
                     f"<td>{'&ge; ' if nw else ''}{t['total_kg'] / 1000:.1f}</td>"
                     f"<td>{t['target_kg'] / 1000:.0f}</td>"
                     f"<td>{t['fill_pct']} %</td><td>{e(t['status'])}"
                     f"{'' if t['closed'] else ' (open)'}</td></tr>")
    lines.append("</table>")
    for name, alt in (("tonnes_per_hour", "tonnes per hour"), ("pass_payloads", "pass payloads"),
                      ("truck_fill", "truck fill"), ("cycle_times", "cycle times")):
        if name in plots:
            b64 = base64.b64encode(plots[name]).decode()
            lines.append(f"<img alt='{alt}' src='data:image/png;base64,{b64}'>")
    if f.cycle_s:
        cs = sorted(f.cycle_s)
        lines.append(f"<p>Cycle time (dump to dump, same truck): median "
                     f"{cs[len(cs) // 2]:.0f} s over {n_of(len(cs), 'cycle', 'cycles')}.</p>")
    lines.append("<h2>Passes not weighed</h2>")
    if f.invalid:
        lines.append("<table id='invalid'><tr><th>pass</th><th>truck</th><th>ended</th>"
                     "<th>reason</th></tr>")
        for p in f.invalid:
            lines.append(f"<tr><td>{p['pass']}</td><td>{p['truck']}</td>"
                         f"<td>{_when(p['end'])}</td><td>{e(str(p['reason']))}</td></tr>")
        lines.append("</table><p>By reason: " + "; ".join(
            f"{e(k)}: {v}" for k, v in f.reasons.most_common()) + "</p>")
    else:
        lines.append("<p>None.</p>")
    lines += _misfit_section(f)
    lines += _calibration_section(f)
    lines += _empty_section(f, plots.get("empty_dipper"))
    lines.append("<p>Tables: <a href='passes.csv'>passes.csv</a>, <a href='trucks.csv'>"
                 "trucks.csv</a>, <a href='hours.csv'>hours.csv</a>"
                 + (", <a href='empties.csv'>empties.csv</a>" if f.empties is not None else "")
                 + ".</p></body></html>")
    page = out / "index.html"
    page.write_text("\n".join(lines), encoding="utf-8")
    return page


def _calibration_section(f: ShiftFigures) -> list[str]:
    """The daemon's calibrations, when one said the model lacks something (health said it
    on the cab and the office all along): of which of this period's passes, for each
    params weighed with in it."""
    said = []
    for note, first, last in f.calibrations:
        got = f.calibration_passes(first, last)
        if got:
            upto = "" if last is None or got[-1] < last else f" to {last}"
            said.append(f"<p class='calibration bad'>{n_of(len(got), 'pass', 'passes')} of "
                        f"this period (pass {got[0]}{' on' if not upto else upto}) were "
                        f"weighed with params whose calibration said: {html.escape(note)}.</p>")
    return ["<h2 id='calibration'>The calibration</h2>", *said] if said else []


def _misfit_section(f: ShiftFigures) -> list[str]:
    """The passes the model did not fit: for the engineer who calibrates the meter, the
    first sign of a machine the model no longer describes, or of a sensor that measures
    something else (they are weighed all the same)."""
    out = ["<h2>Passes the model did not fit</h2>"]
    if not f.misfits:
        out.append("<p>The pass log records no misfit for these passes (written before "
                   "2026-11-29).</p>")
        return out
    ms = sorted(f.misfits)
    out.append(f"<p>A pass's misfit is the mean square of the model's residuals over it, in "
               f"units of the calibration's noise: about 1 when the model holds. Median "
               f"{ms[len(ms) // 2]:.2f} over {n_of(len(ms), 'pass', 'passes')}. It is not "
               "a check of the weight: a machine changed since its calibration in a way "
               "that looks like payload (a dipper 5 % heavier) leaves it near 1 and every "
               "pass tonnes heavy; the empty dipper weighed on the returns says that (the "
               "next section, and the daemon's health) and a known load does.</p>")
    if not f.misfit_high:
        out.append(f"<p id='misfit'>None above {MISFIT_WARN:g}.</p>")
        return out
    out.append(f"<p id='misfit' class='bad'>{n_of(len(f.misfit_high), 'pass', 'passes')} "
               f"above {MISFIT_WARN:g}: the model lacks something this machine does "
               "(<code>shoveld diagnose</code> on its signals names it) or a sensor measures "
               "something else (the crowd laser on something other than the handle). A "
               "misfit alone does not stop a pass being weighed.</p>")
    out.append("<table id='misfits'><tr><th>pass</th><th>truck</th><th>ended</th>"
               "<th>payload (t)</th><th>misfit</th></tr>")
    for p in f.misfit_high:
        kg = p["payload_kg"]
        weighed = "not weighed" if kg is None else f"{kg / 1000:.1f}"
        out.append(f"<tr><td>{p['pass']}</td><td>{p['truck']}</td><td>{_when(p['end'])}</td>"
                   f"<td>{weighed}</td><td>{float(p['misfit']):.1f}</td></tr>")
    out.append("</table>")
    return out


def _empty_section(f: ShiftFigures, png: bytes | None) -> list[str]:
    """The empty dipper weighed on each return: zero while the calibration fits the
    machine and nothing stays in the dipper. For the engineer who calibrates the meter,
    the check of the weight that the misfit is not (a dipper rebuilt heavier shows here,
    not there), and its trend over the shift."""
    out = ["<h2>The empty dipper on the returns</h2>"]
    if f.empties is None:
        out.append("<p>The pass log records no empty-dipper checks (written before "
                   "2026-11-29's schema 3).</p>")
        return out
    if not f.empties:
        out.append("<p>No return was weighed in this period.</p>")
        return out
    kg = sorted(e["payload_kg"] for e in f.empties)
    last = f.empties[-1]
    warn = last["warn_kg"]
    out.append(f"<p>The daemon weighs the empty dipper on each return after a dump, with "
               f"the passes' equations; it checks, it corrects nothing. "
               f"{n_of(len(kg), 'return', 'returns')}: median {kg[len(kg) // 2]:+.0f} kg, "
               f"from {kg[0]:+.0f} to {kg[-1]:+.0f} kg; the median of the last returns at "
               f"the end {last['median_kg']:+.0f} kg, against the daemon's level of "
               f"±{warn:.0f} kg.</p>")
    beyond = f.empty_beyond
    if not beyond:
        out.append(f"<p id='empty'>The median of the last returns stayed within "
                   f"±{warn:.0f} kg.</p>")
    else:
        first = beyond[0]
        out.append(f"<p id='empty' class='bad'>The median of the last returns was beyond "
                   f"the level at {n_of(len(beyond), 'return', 'returns')}, the first ending "
                   f"{_when(first['end'])} (median {first['median_kg']:+.0f} kg): material "
                   "stays in the dipper, or the machine has changed since its calibration "
                   "(weigh a known load, calibrate again), or the model lacks something the "
                   "machine does in its fast returns (<code>shoveld diagnose</code>). The "
                   "passes may be off too, by less or more than the empty weight.</p>")
    if png is not None:
        b64 = base64.b64encode(png).decode()
        out.append(f"<img alt='the empty dipper on the returns' "
                   f"src='data:image/png;base64,{b64}'>")
    return out
