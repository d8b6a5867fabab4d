"""Phases and payload of the live engine on simulated cycles, and the CLI round trip."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from shoveld.cli import main
from shoveld.engine.offline import estimate_table
from shoveld.model.params import ModelParams, load_params
from shoveld.payload.trucks import Truck, rule_101020, rule_summary, truck_line
from shoveld.sim.scenario import RATED_PAYLOAD_KG, SimResult, simulate_cycles


def match(est_start: float, res: SimResult) -> float:
    for p in res.passes:
        if abs(p.phases["dig"][0] - est_start) < 2.0:
            return p.payload_kg
    raise AssertionError(f"no simulated pass starts near {est_start}")


def test_every_pass_found_and_accurate(params: ModelParams, cycles: SimResult) -> None:
    est = estimate_table(cycles.table, params)
    assert len(est.passes) == len(cycles.passes)
    err = np.array([p.payload_kg - match(p.start_s, cycles) for p in est.passes])
    assert all(p.valid for p in est.passes)
    assert np.max(np.abs(err)) < 0.015 * RATED_PAYLOAD_KG
    # The reported confidence is not absurd: errors within 4 sigma.
    stds = np.array([p.std_kg for p in est.passes])
    assert np.all(np.abs(err) < 4 * stds + 50)


def test_phases_follow_the_truth(params: ModelParams, cycles: SimResult) -> None:
    est = estimate_table(cycles.table, params)
    for p, tp in zip(est.passes, cycles.passes, strict=True):
        assert abs(p.start_s - tp.phases["dig"][0]) < 1.5
        # Final at the dump: after the swing ends, before the return begins.
        assert tp.phases["swing"][1] - 0.2 < p.end_s < tp.phases["return"][0] + 0.5


def test_empty_dipper(params: ModelParams) -> None:
    res = simulate_cycles(3, seed=104, payloads=[0.0, 0.0, 0.0])
    est = estimate_table(res.table, params)
    assert len(est.passes) == 3
    assert all(abs(p.payload_kg) < 400 for p in est.passes), [p.payload_kg for p in est.passes]


def test_missing_current_makes_no_number(params: ModelParams) -> None:
    res = simulate_cycles(2, seed=105, payload_range=(20000, 30000))
    res.table.columns["hoist2_a"][:] = np.nan
    est = estimate_table(res.table, params)
    assert est.passes and not any(p.valid for p in est.passes)
    assert all(p.as_dict()["payload_kg"] is None for p in est.passes)


def test_trucks_and_rule() -> None:
    def truck(i: int, total: float) -> Truck:
        return Truck(i, 100.0, [{"payload_kg": total, "std_kg": 1.0}])

    assert truck(1, 105).status == "ok" and truck(1, 115).status == "over_110"
    assert truck(1, 125).status == "over_120" and truck(1, 80).status == "under"
    ok = [truck(i, 95) for i in range(9)] + [truck(9, 115)]
    assert rule_101020(ok)["compliant"]
    assert not rule_101020(ok[:8] + [truck(8, 115), truck(9, 115)])["compliant"]
    assert not rule_101020([truck(1, 90), truck(2, 121)])["compliant"]


def test_a_truck_with_a_pass_not_weighed_is_known_only_from_below() -> None:
    """A pass the engine did not weigh still went into the truck: its weighed total is a
    lower bound, so the truck is neither under nor within target, and the 10/10/20 rule
    leaves it out of the mean and the 110 % share, but counts it over 120 % when its
    weighed passes alone are."""
    def truck(i: int, weighed: float, not_weighed: int = 0) -> Truck:
        return Truck(i, 100.0, [{"payload_kg": weighed, "std_kg": 1.0}]
                     + [{"payload_kg": None, "std_kg": None, "valid": False}] * not_weighed)

    assert truck(1, 80, 1).status == "incomplete" and truck(1, 105, 2).status == "incomplete"
    assert truck(1, 115, 1).status == "over_110" and truck(1, 125, 1).status == "over_120"
    d = truck(1, 80, 2).as_dict()
    assert (d["passes"], d["invalid_passes"], d["total_kg"]) == (3, 2, 80.0)
    # nine trucks at 95 %, one short by a pass not weighed: the mean is the nine's, not
    # pulled down by the short one
    fleet = [truck(i, 95) for i in range(9)] + [truck(9, 40, 1)]
    r = rule_101020(fleet)
    assert (r["trucks"], r["not_judged"], r["mean_pct"]) == (9, 1, 95.0) and r["compliant"]
    assert "9 closed trucks: mean 95.0 % of target" in rule_summary(r)
    assert "; 1 truck with a pass not weighed not judged -> compliant" in rule_summary(r)
    # one over 110 % in ten is allowed, but it is judged among the nine that were weighed
    r = rule_101020(fleet[:8] + [truck(8, 115)] + fleet[9:])
    assert r["over_110_pct"] == 11.1 and not r["compliant"]
    # over 120 % by its weighed passes alone: an overload whatever was not weighed
    r = rule_101020([truck(1, 95), truck(2, 121, 1)])
    assert (r["trucks"], r["not_judged"], r["over_120"]) == (1, 1, 1) and not r["compliant"]
    r = rule_101020([truck(1, 60, 1)])
    assert (r["trucks"], r["not_judged"], r["compliant"]) == (0, 1, True)
    assert rule_summary(r) == "no truck judged: 1 truck with a pass not weighed not judged"
    assert rule_summary(rule_101020([])) == "no closed truck"
    assert truck_line(truck(3, 40, 1).as_dict()) == \
        "2 passes (1 not weighed), at least 40 kg of 100 kg (40.0 %), incomplete"
    assert truck_line(truck(3, 40).as_dict()) == "1 pass, 40 kg of 100 kg (40.0 %), under"


def test_cli_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """sim -> calibrate -> estimate through the command line, JSON out."""
    e, l, c, p = (str(tmp_path / n) for n in ("e.csv", "l.csv", "c.csv", "p.toml"))
    assert main(["sim", "--scenario", "calibration", "--load", "0", "--seed", "5", "--out", e]) == 0
    assert main(["sim", "--scenario", "calibration", "--load", "8420", "--seed", "6",
                 "--out", l]) == 0
    assert main(["sim", "--passes", "5", "--seed", "7", "--out", c]) == 0
    assert main(["calibrate", "--out", p, e, l]) == 0
    capsys.readouterr()
    assert main(["estimate", "--params", p, "--json", c]) == 0
    out = capsys.readouterr()
    lines = [json.loads(x) for x in out.out.splitlines()]
    truth = json.loads(Path(c + ".truth.json").read_text())["passes"]
    assert len(lines) == len(truth) == 5
    for got, tp in zip(lines, truth, strict=True):
        assert {"pass", "start_s", "end_s", "payload_kg", "std_kg"} <= set(got)
        assert abs(got["payload_kg"] - tp["payload_kg"]) < 500
    summary = json.loads(out.err.strip().splitlines()[-1])
    assert summary["trucks"] and summary["rule_10_10_20"]["trucks"] >= 1
    assert "warning" not in out.err  # a simulated crowd never jumps (checks.crowd_jumps)
    # a table without a pass (a trial) is said to have none, not answered with nothing
    assert main(["estimate", "--params", p, e]) == 0
    out = capsys.readouterr()
    assert out.out == ""
    assert f"{e}: no pass (no dig followed by a lift and a swing in its" in out.err


def test_calibrate_takes_scale_verified_passes_with_the_trials(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--verified``: the weighed passes enter the identification beside the trials (they
    carry a full dipper's currents); a table without any is refused in one line."""
    e, l, v, u = (str(tmp_path / n) for n in ("e.csv", "l.csv", "v.csv", "u.csv"))
    p0, p1 = str(tmp_path / "p0.toml"), str(tmp_path / "p1.toml")
    for args in (["--scenario", "calibration", "--load", "0", "--seed", "5", "--out", e],
                 ["--scenario", "calibration", "--load", "8420", "--seed", "6", "--out", l],
                 ["--passes", "6", "--verified-fraction", "1", "--seed", "8", "--out", v],
                 ["--passes", "2", "--verified-fraction", "0", "--seed", "9", "--out", u]):
        assert main(["sim", *args]) == 0
    assert main(["calibrate", "--out", p0, e, l]) == 0
    assert main(["calibrate", "--out", p1, e, l, "--verified", v]) == 0
    err = capsys.readouterr().err
    assert "identified with 6 verified passes of 6 in 1 table" in err
    trials, both = load_params(p0), load_params(p1)
    used = {Path(k).name: x for k, x in both.fit["excluded"].items()}
    assert set(used) == {"e.csv", "l.csv", "v.csv (verified passes)"}, used
    assert used["v.csv (verified passes)"]["used"] > 1000
    assert [Path(k).name for k in trials.fit["excluded"]] == ["e.csv", "l.csv"]
    assert not np.allclose(trials.values, both.values)
    # the passes fit as well as the trials: said in the report, recorded, no warning
    ratio = both.fit["passes_to_trials_rms"]
    assert set(ratio) == {"hoist", "crowd"} and all(0.8 < r < 1.5 for r in ratio.values())
    assert "warning" not in err and "passes_to_trials_rms" not in trials.fit
    assert main(["calibrate", "--out", p1, e, l, "--verified", u]) == 2
    err = capsys.readouterr().err.strip()
    assert "--verified" in err and "u.csv" in err and "no pass with a verified payload" in err
    assert len(err.splitlines()) == 1


def test_calibrate_corrects_for_the_angles_noise_by_default(tmp_path: Path) -> None:
    """The fit takes the handle angle's and the crowd extension's noise out (errors in
    variables) and records the noise it took, which is the simulated sensors' (0.03 deg,
    2 mm); with ``--no-angle-noise`` it does not, and the file says nothing of it."""
    e, l = str(tmp_path / "e.csv"), str(tmp_path / "l.csv")
    p0, p1 = str(tmp_path / "p0.toml"), str(tmp_path / "p1.toml")
    for args in (["--load", "0", "--seed", "5", "--out", e],
                 ["--load", "8420", "--seed", "6", "--out", l]):
        assert main(["sim", "--scenario", "calibration", *args]) == 0
    assert main(["calibrate", "--no-angle-noise", "--out", p0, e, l]) == 0
    assert main(["calibrate", "--out", p1, e, l]) == 0
    plain, corrected = load_params(p0), load_params(p1)
    assert "position_noise" not in plain.fit
    took = corrected.fit["position_noise"]
    assert took["handle_deg"] == pytest.approx(0.03, rel=0.15)
    assert took["crowd_m"] == pytest.approx(0.002, rel=0.15)
    assert corrected.fit["input_noise_corrected"]
    assert not np.allclose(plain.values, corrected.values, rtol=1e-6)


def test_cli_bad_input_is_one_clear_line(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,handle_deg\n0,1\n")
    assert main(["calibrate", "--out", str(tmp_path / "p.toml"), str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv:1" in err and "missing column" in err


def test_every_subcommand_has_help(capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sub.choices is not None
    assert {"sim", "calibrate", "estimate"} <= set(sub.choices)
    for name in sub.choices:
        with pytest.raises(SystemExit) as ei:
            main([name, "--help"])
        assert ei.value.code == 0


def test_an_abandoned_cycle_leaves_no_gap_in_pass_numbers(params: ModelParams,
                                                          cycles: SimResult) -> None:
    """A dig that lifts and then stops (no dump) makes no pass and uses no pass number."""
    from shoveld.cycle.phases import PhaseConfig
    from shoveld.engine.loop import Engine, EngineConfig, LiveEstimate, PassResult
    from shoveld.sample import Sample, samples_from_table

    real = list(samples_from_table(cycles.table))
    dt = real[1].time_s - real[0].time_s
    s0 = real[0]
    hold = PhaseConfig().idle_hold_s
    # handle angle of the abandoned cycle: still in the tuck, a dig rising out of it, a
    # stop above the bank for longer than idle_hold_s, then back to where the data starts
    knots = [(0.0, -40.0), (3.0, -40.0), (11.0, 0.0), (13.0 + hold, 0.0),
             (21.0 + hold, s0.handle_deg), (23.0 + hold, s0.handle_deg)]
    n = int(knots[-1][0] / dt)
    ts = np.arange(n) * dt
    th = np.interp(ts, [k[0] for k in knots], [k[1] for k in knots])
    pre = [Sample(float(t), handle_deg=float(a), crowd_m=s0.crowd_m, swing_deg=s0.swing_deg,
                  boom_deg=s0.boom_deg) for t, a in zip(ts, th, strict=True)]
    shift = n * dt - s0.time_s
    data = pre + [dataclasses.replace(s, time_s=s.time_s + shift) for s in real]
    eng = Engine(params, EngineConfig(rate_hz=1.0 / dt))
    phases: list[str] = []
    passes: list[PassResult] = []
    for s in data:
        for ev in eng.step(s):
            if isinstance(ev, LiveEstimate) and (not phases or phases[-1] != ev.phase):
                phases.append(ev.phase)
            elif isinstance(ev, PassResult):
                passes.append(ev)
    # the cycle was really abandoned: dig, lift, then idle before any dump
    assert phases[:4] == ["idle", "dig", "lift", "idle"], phases[:6]
    assert [p.index for p in passes] == list(range(1, len(cycles.passes) + 1))
    assert all(p.valid for p in passes)


def test_sim_of_one_pass_says_one_pass(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "one.csv"
    assert main(["sim", "--passes", "1", "--seed", "3", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert " samples, " in said and ", 1 pass) and " in said, said  # not "1 passes"


def test_calibrate_says_when_the_verified_passes_fit_worse_than_the_trials(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A swing the model lacks: the trials do not swing and fit; the verified passes do,
    and their residuals are twice the trials' or more. The calibration's noise takes that
    in, so the daemon's misfit will not see it: ``calibrate`` says so, in one line."""
    e, l, v = (str(tmp_path / n) for n in ("e.csv", "l.csv", "v.csv"))
    swing = ["--effect", "swing_centrifugal=2.5"]
    for args in (["--scenario", "calibration", "--load", "0", "--seed", "5", "--out", e],
                 ["--scenario", "calibration", "--load", "8420", "--seed", "6", "--out", l],
                 ["--passes", "6", "--verified-fraction", "1", "--seed", "8", "--out", v]):
        assert main(["sim", *args, *swing]) == 0
    out = str(tmp_path / "p.toml")
    capsys.readouterr()
    assert main(["calibrate", "--out", out, e, l, "--verified", v]) == 0
    captured = capsys.readouterr()
    warned = [x for x in captured.err.splitlines() if x.startswith("warning:")]
    ratio = load_params(out).fit["passes_to_trials_rms"]
    assert max(ratio.values()) > 1.5, ratio
    assert len(warned) == 1 and "shoveld diagnose names it" in warned[0], captured.err
    assert "residual RMS of the verified passes over the trials': hoist" in captured.out
