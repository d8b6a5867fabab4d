"""The realistic simulated machine, and the identification's statistics on it.

A simulator that shares the model's assumptions always fits it; these tests hold the
estimator to what real transducers and drives do (``shoveld.sim.machine``): offsets
and gain errors, a 12-bit ADC, noise growing with the reading, a wandering hoist
split, a drifting handle sensor and a hoist field weakened above base speed. The full
statistics over many machines are ``bench/payload_accuracy.py``'s; here at a size CI
can afford.
"""

from __future__ import annotations

import numpy as np
import pytest

from shoveld.engine.offline import estimate_table
from shoveld.identify.calibrate import Calibrator
from shoveld.model.params import ModelParams
from shoveld.model.terms import knot_group
from shoveld.sim.machine import Channel, FieldDrive, Machine
from shoveld.sim.scenario import SimResult, simulate_calibration, simulate_cycles

N_MACHINES = 20
"""Machines drawn for the coverage test: the issue's "at least 20" (the bench uses 24
others)."""


def test_a_channel_reads_like_a_hall_transducer_on_a_12_bit_adc() -> None:
    ch = Channel(offset_a=3.0, gain=0.004, noise_a=2.5, noise_rel=0.002, bits=12)
    rng = np.random.default_rng(0)
    x = np.full(20000, 500.0)
    y = ch.read(x, rng)
    lsb = 8000.0 / 4096
    assert np.allclose(y / lsb, np.round(y / lsb))
    assert np.mean(y) == pytest.approx(500 * 1.004 + 3.0, abs=0.1)
    assert np.std(y) == pytest.approx(np.hypot(2.5, 1.0), rel=0.05)
    assert ch.read(np.array([9000.0]), rng)[0] < 4000.0  # the ADC clips


def test_the_drive_weakens_the_field_above_base_speed_both_ways() -> None:
    fd = FieldDrive(hoist_base_m_s=1.7, lower_base_m_s=0.9)
    target = fd.field_target(np.array([0.0, -1.0, -2.4, 0.5, 1.8, 5.0]))
    assert target[0] == target[1] == target[3] == pytest.approx(70.0)
    assert 30.0 < target[2] < 65.0  # hoisting at 1.4 x base speed
    assert 30.0 <= target[4] < 65.0 and target[5] == pytest.approx(30.0)
    assert fd.flux_ratio(fd.field_for(np.array([0.5])))[0] == pytest.approx(0.5)


def test_seeds_draw_machines_and_files_of_one_machine_share_its_sensors() -> None:
    a, b = Machine.draw(1), Machine.draw(2)
    assert a.sensors.hoist1.offset_a != b.sensors.hoist1.offset_a
    assert a.plant.Md != b.plant.Md
    assert Machine.draw(1) == a
    cal = simulate_calibration(0.0, seed=5, machine=a, n_poses=4, free_motion_s=10,
                               fast_moves=0)
    assert cal.table.meta["shovel"] == "sim-ph2100-m1"
    assert cal.truth["machine"]["identified_truth"]["i_H0"] == pytest.approx(
        a.sensors.hoist1.offset_a + a.sensors.hoist2.offset_a)


@pytest.fixture(scope="module")
def machine_runs() -> list[tuple[Machine, ModelParams]]:
    out = []
    for seed in range(301, 301 + N_MACHINES):
        m = Machine.draw(seed)
        cal = Calibrator().fit([simulate_calibration(0.0, seed=10 * seed, machine=m).table,
                                simulate_calibration(8420.0, seed=10 * seed + 1,
                                                     machine=m).table])
        assert cal.params_ is not None
        out.append((m, cal.params_))
    return out


PAYLOAD_PARAMS = ("Md", "MdLc", "K_H", "K_C", "i_H0", "i_C0", "J")
"""What the payload rests on: gravity, the force constants at the nominal field, the
offsets, and the arm's inertia (biased +5 standard errors until the angles' smoothing
kept the fast strokes' accelerations; short of 90 % coverage with MdLc and the offsets
until the handle sensor's drift was counted in the standard errors)."""


@pytest.mark.parametrize("name", PAYLOAD_PARAMS)
def test_standard_errors_are_honest_over_machines(
        machine_runs: list[tuple[Machine, ModelParams]], name: str) -> None:
    """The true value within 2 standard errors in at least 90 % of the machines, and the
    mean error under half the mean standard error."""
    errs, ses = [], []
    for m, p in machine_runs:
        tr = m.truth_for(p)
        errs.append(p.get(name) - tr[name])
        ses.append(float(p.stderr[p.names.index(name)]))
    e, se = np.array(errs), np.array(ses)
    assert np.mean(np.abs(e) <= 2 * se) >= 0.9, (name, e / se)
    assert abs(e.mean()) < 0.5 * se.mean(), (name, e.mean(), se.mean())


def test_the_field_curve_is_unbiased_over_machines(
        machine_runs: list[tuple[Machine, ModelParams]]) -> None:
    """Each knot of K_H(i_f) below the nominal field, grouped by the nearest 10 A (the
    calibration places them where each machine's data have field currents): the true
    value within 2 standard errors in at least 90 % of the machines, and the mean error
    under half the mean standard error. The lowest knot was +1.5 standard errors high
    (73 % covered) over 120 machines until the curve went on along its slope below it,
    the spline's ends became not-a-knot and the field channel's noise was taken out of
    the score (docs/engine.md)."""
    groups: dict[str, list[tuple[float, float]]] = {}
    for m, p in machine_runs:
        tr = m.truth_for(p)
        for n, v, se in zip(p.names, p.values, p.stderr, strict=True):
            if n.startswith("K_H_f"):
                groups.setdefault(knot_group(n), []).append(
                    (float(v) - tr[n], float(se)))
    held = {g: rows for g, rows in groups.items() if len(rows) >= 10}
    assert len(held) >= 3, sorted(groups)
    for g, rows in sorted(held.items()):
        e, se = np.array(rows).T
        assert np.mean(np.abs(e) <= 2 * se) >= 0.9, (g, e / se)
        assert abs(e.mean()) < 0.5 * se.mean(), (g, e.mean() / se.mean())


def test_the_angles_noise_is_taken_out_of_the_identification() -> None:
    """Errors in variables: the rates and accelerations are smoothed from noisy angle
    and extension readings, and the fit's equations use them, so their noise biases it
    (the arm's inertia J towards zero, K_C up: +0.3-0.5 standard errors over 24-120
    machines at the simulator's noise). With the sensors twice as noisy, on four
    machines, J is -2.5 standard errors low without the correction
    (``Calibrator.position_noise``); with it, within half a standard error on average,
    and K_C's bias at most half what it was."""
    from dataclasses import replace

    bias: dict[bool, dict[str, list[float]]] = {False: {}, True: {}}
    for seed in range(301, 305):
        m = Machine.draw(seed)
        m = replace(m, sensors=replace(m.sensors, crowd_m=2 * m.sensors.crowd_m,
                                       handle_deg=2 * m.sensors.handle_deg))
        tables = [simulate_calibration(0.0, seed=10 * seed, machine=m).table,
                  simulate_calibration(8420.0, seed=10 * seed + 1, machine=m).table]
        for corrected in (False, True):
            p = Calibrator(position_noise=corrected).fit(tables).params_
            assert p is not None
            tr = m.truth_for(p)
            for name in ("J", "K_C"):
                z = (p.get(name) - tr[name]) / float(p.stderr[p.names.index(name)])
                bias[corrected].setdefault(name, []).append(z)
    before = {n: float(np.mean(z)) for n, z in bias[False].items()}
    after = {n: float(np.mean(z)) for n, z in bias[True].items()}
    assert before["J"] < -1.5, before  # the noise really biases the fit
    assert abs(after["J"]) < 0.5, after
    assert abs(after["K_C"]) <= 0.5 * abs(before["K_C"]), (before, after)


@pytest.mark.parametrize("name", ("fv3", "fc3", "fv4", "fc4"))
def test_friction_is_unbiased_over_machines(
        machine_runs: list[tuple[Machine, ModelParams]], name: str) -> None:
    """The friction pairs were biased by 1-4 standard errors (Coulomb low, viscous high;
    the crowd's pair a strict xfail here) until held poses stopped taking the noise the
    fit differentiated for motion. Their coverage is the bench's (120 machines: 96-99 %);
    20 machines measure a share near 95 % too coarsely to hold it to 90 %."""
    e = np.array([p.get(name) - m.truth_for(p)[name] for m, p in machine_runs])
    se = np.array([float(p.stderr[p.names.index(name)]) for _, p in machine_runs])
    assert abs(e.mean()) < 0.5 * se.mean(), (name, e / se)


@pytest.fixture(scope="module")
def fast_lifts(machine_runs: list[tuple[Machine, ModelParams]]
               ) -> tuple[SimResult, ModelParams]:
    m, p = machine_runs[0]
    return simulate_cycles(12, seed=909, machine=m, payload_range=(3000.0, 35000.0),
                           truck_target_kg=None), p


def test_every_pass_has_a_payload_when_the_field_weakens(
        fast_lifts: tuple[SimResult, ModelParams]) -> None:
    """Fast lifts run on a weakened hoist field; no pass may lose its payload for it."""
    res, p = fast_lifts
    t, field = res.table.time, res.table.columns["hoist_field_a"]
    weak = [tp for tp in res.passes if np.nanmin(
        field[(t >= tp.phases["lift"][0]) & (t < tp.phases["swing"][0])]) < 60.0]
    assert len(weak) >= 3  # the scenario really weakens the field
    est = estimate_table(res.table, p)
    assert len(est.passes) == len(res.passes) and all(q.valid for q in est.passes)
    err = np.array([q.payload_kg - tp.payload_kg for q, tp in zip(est.passes, res.passes,
                                                                   strict=True)])
    std = np.array([q.std_kg for q in est.passes])
    crb = np.array([tp.crb_kg for tp in res.passes])
    assert np.all(np.abs(err) < 4 * std)
    assert np.all((crb > 10) & (crb < 200))  # "a few tens of kg" per pass
    assert np.sqrt(np.mean(err**2)) < 3 * crb.mean()


def test_friction_near_standstill_does_not_pull_the_payload(
        machine_runs: list[tuple[Machine, ModelParams]], monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulated machine's Coulomb friction switches over a narrower band of speed
    than the model's smoothed sign (real friction is its own shape: stiction, the Stribeck
    dip). Where a joint passes through standstill in swing the model's friction is then
    wrong by up to fc for several samples. Weighting those samples by the sign's own
    uncertainty (``Friction.column_spread``) must make the payload better on every one of
    four machines (measured: RMS 64 against 80, 65/70, 75/81 and 50/55 kg over 12 passes)."""
    from shoveld.model.terms import Friction

    runs = [(simulate_cycles(12, seed=909, machine=m, payload_range=(3000.0, 35000.0),
                             truck_target_kg=None), p) for m, p in machine_runs[:4]]

    def rms(res: SimResult, p: ModelParams) -> float:
        est = estimate_table(res.table, p)
        err = [q.payload_kg - tp.payload_kg for q, tp in zip(est.passes, res.passes,
                                                              strict=True)]
        return float(np.sqrt(np.mean(np.square(err))))

    weighted = [rms(res, p) for res, p in runs]
    monkeypatch.setattr(Friction, "spread_params", ())
    unweighted = [rms(res, p) for res, p in runs]
    assert all(w < u for w, u in zip(weighted, unweighted, strict=True)), (weighted, unweighted)
