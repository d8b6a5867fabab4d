"""The model's extension terms against the simulator's independent physics.

The simulator writes each effect in Cartesian/virtual-work form (3D bodies, rope
elements, tilted gravity, ...); the model writes it analytically. On noise-free
simulated motion, the extended model with the true parameters must explain what the
base model cannot; that checks both derivations against each other.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from shoveld.diagnose import MODELLED_BY_BASE
from shoveld.kinematics.offline import offline_kinematics
from shoveld.model import G, Kinematics, Model
from shoveld.model.effects import (
    DRIVE_STREAM,
    EFFECT_TERMS,
    BoomSuspensionSpring,
    CurrentSaturation,
    ExtensionTerm,
    SensorTimeSkew,
    SwingCentrifugal,
    _delay_errors,
    _parabola,
    _unit_hoist,
    _unit_hoist_dboom,
)
from shoveld.model.params import ModelParams, load_params, save_params
from shoveld.model.terms import TERMS
from shoveld.sample import samples_from_table
from shoveld.sim.effects import (
    DRUM_XY,
    SIM_EFFECTS,
    BoomSuspensionSpringEffect,
    PayloadCogOffsetEffect,
    make_effects,
)
from shoveld.sim.plant import PlantParams
from shoveld.sim.scenario import SensorNoise, simulate_cycles
from tests.diagnose.conftest import session

QUIET = SensorNoise().scaled(1e-9)


def _kin(n: int = 50, seed: int = 0) -> Kinematics:
    rng = np.random.default_rng(seed)
    z = np.zeros(n)
    return Kinematics(t=np.arange(n) * 0.02, th=rng.uniform(-0.6, 0.5, n),
                      thd=rng.normal(0, 0.2, n), thdd=rng.normal(0, 0.3, n),
                      d=rng.uniform(6.5, 10.5, n), dd=rng.normal(0, 0.2, n),
                      ddd=rng.normal(0, 0.3, n), boom=np.radians(rng.uniform(43, 47, n)),
                      i_h=rng.uniform(150, 500, n), i_c=rng.uniform(-50, 130, n),
                      i_hf=rng.uniform(66, 80, n), swing=z, swing_rate=rng.normal(0, 0.4, n),
                      swing_acc=z, roll=np.radians(rng.normal(0, 3, n)),
                      pitch=np.radians(rng.normal(0, 3, n)))


def test_library_is_registered_on_both_sides() -> None:
    assert set(EFFECT_TERMS) <= set(TERMS)
    # every simulated effect has a term to find it, except those the base model carries
    assert set(EFFECT_TERMS) == set(SIM_EFFECTS) - set(MODELLED_BY_BASE)
    assert set(MODELLED_BY_BASE.values()) <= set(TERMS)
    for name in EFFECT_TERMS:
        assert getattr(TERMS[name], "cause", ""), name
        lo, hi = SIM_EFFECTS[name].typical_range
        assert lo < hi


def test_rope_derivative_by_boom_matches_finite_difference() -> None:
    k = _kin()
    eps = 1e-6
    names = ("t", "th", "thd", "thdd", "d", "dd", "ddd", "boom", "i_h", "i_c", "i_hf", "swing",
             "swing_rate", "swing_acc", "roll", "pitch")
    up = Kinematics(**{n: getattr(k, n) + (eps if n == "boom" else 0) for n in names})
    dn = Kinematics(**{n: getattr(k, n) - (eps if n == "boom" else 0) for n in names})
    num = [(a - b) / (2 * eps) for a, b in zip(_unit_hoist(up), _unit_hoist(dn), strict=True)]
    ana = _unit_hoist_dboom(k)
    for x, y in zip(num, ana, strict=True):
        assert np.allclose(x, y, rtol=1e-5, atol=1e-6)


def test_terms_without_their_excitation_change_nothing() -> None:
    """No swing, no tilt, nominal field, no payload: the extended regressor reduces to
    the base one (the extension columns are zero or multiply zero)."""
    k = _kin()
    k.swing_rate[:] = 0.0
    k.roll[:] = 0.0
    k.pitch[:] = 0.0
    k.i_hf[:] = 70.0
    base = Model.from_names([])
    wb, phib, _ = base.regressor(k)
    for name in ("swing_centrifugal", "ground_slope", "hoist_field_weakening"):
        m = Model.from_names([name])
        w, phi, _ = m.regressor(k)
        assert np.allclose(w[:, :, :wb.shape[2]], wb)
        assert np.allclose(w[:, :, wb.shape[2]:], 0.0, atol=1e-9)
        assert np.allclose(phi, phib)


@pytest.mark.parametrize("name", sorted(EFFECT_TERMS))
def test_no_extension_column_carries_the_measured_current_it_predicts(name: str) -> None:
    """The currents are the outputs. A column built from a sample's own measured current
    would let the fit predict that sample's noise: on realistic data the cubic
    saturation term took 2.8 % of the held-out residual that way from a machine without
    saturation (1.0 % once it used the neighbours' estimate). Terms nonlinear in a
    current take it from the neighbouring samples (``i_h_est``, ``i_c_est``)."""
    k = _kin()
    k.i_h_est, k.i_c_est = k.i_h.copy(), k.i_c.copy()
    m = Model.from_names([name])
    w0, _, _ = m.regressor(k)
    nb = Model.from_names([]).regressor(k)[0].shape[2]
    k.i_h = k.i_h + 37.0
    k.i_c = k.i_c + 23.0
    w1, _, _ = m.regressor(k)
    assert np.allclose(w1[:, :, nb:], w0[:, :, nb:])


def _truth(effect: str, mag: float
           ) -> tuple[list[str], dict[str, dict[str, float]], dict[str, float]]:
    """Model terms, hyper-parameters and true parameter values for a sim effect."""
    pp = PlantParams()
    vals = {"Md": pp.Md, "MdLc": pp.Md * pp.Lc, "K_H": pp.K_H, "K_C": pp.K_C,
            "J": pp.Izz + pp.Md * pp.Lc**2, "fv3": pp.fv3, "fc3": pp.fc3, "fv4": pp.fv4,
            "fc4": pp.fc4, "i_H0": 0.0, "i_C0": 0.0}
    hyper: dict[str, dict[str, float]] = {}
    if effect == "swing_centrifugal":
        hyper = {effect: {"R0_m": mag}}
        vals["dJ_sw"] = 0.0
    elif effect == "payload_cog_offset":
        ang = math.radians(PayloadCogOffsetEffect.angle_deg)
        vals["cog_fwd"], vals["cog_up"] = mag * math.cos(ang), mag * math.sin(ang)
    elif effect == "hoist_rope_mass":
        # the drum-side rope's constant tension is what a hoist current offset does
        vals["rope_kg_m"], vals["i_H0"] = mag, mag * G * DRUM_XY[1] / pp.K_H
    elif effect == "ground_slope":
        vals["K_H_pitch"] = pp.K_H
    return [effect], hyper, vals


@pytest.mark.parametrize("effect,mag", [("swing_centrifugal", 4.5),
                                        ("payload_cog_offset", 1.0),
                                        ("hoist_rope_mass", 120.0),
                                        ("ground_slope", 5.0)])
def test_model_term_explains_the_simulated_effect(effect: str, mag: float) -> None:
    """Noise-free cycles with the effect: with the true parameters, the extended model's
    residual over the swing is a fraction of the base model's."""
    res = simulate_cycles(3, seed=7, payload_range=(20000.0, 30000.0), truck_target_kg=None,
                          effects=make_effects({effect: mag}), noise=QUIET)
    kin, ok = offline_kinematics(res.table)
    assert res.motion is not None and res.ctx is not None  # simulate_cycles keeps both
    m_true = res.motion.payload[res.ctx["sample_index"]]
    sel = np.zeros(len(kin), dtype=bool)
    for p in res.passes:
        t = kin.t
        sel |= (t >= p.phases["swing"][0] + 0.5) & (t < p.phases["swing"][1] - 0.5)
    sel &= ok
    k = kin.take(sel)
    terms, hyper, vals = _truth(effect, mag)
    base = Model.from_names([])
    ext = Model.from_names(terms, hyper)
    r_base = base.residual(k, np.array([vals[n] for n in base.param_names]), m_true[sel])
    # offsets act on the measured currents, outside the force residual
    assert k.i_h_est is not None  # Kinematics.__post_init__ sets it
    k_ext = dataclasses.replace(k, i_h=k.i_h - vals["i_H0"], i_h_est=k.i_h_est - vals["i_H0"])
    r_ext = ext.residual(k_ext, np.array([vals[n] for n in ext.param_names]), m_true[sel])
    rms_b = np.sqrt(np.mean(r_base**2, axis=0))
    rms_e = np.sqrt(np.mean(r_ext**2, axis=0))
    assert rms_e[0] < 0.35 * rms_b[0], (rms_b, rms_e)


def test_stream_delay_matches_the_offline_transform() -> None:
    res = simulate_cycles(1, seed=3, payload_range=(10000.0, 10000.0), truck_target_kg=None)
    term = SensorTimeSkew(delay_s=0.1)
    cols = term.transform(dict(res.table.columns))
    live = term.stream()
    assert live is not None
    out = [live(s) for s in samples_from_table(res.table)]
    for name in DRIVE_STREAM[:4]:
        got = np.array([getattr(s, name) for s in out])
        want = cols[name]
        both = np.isfinite(got) & np.isfinite(want)
        assert both.sum() > len(got) - 10
        assert np.allclose(got[both], want[both])
        assert np.array_equal(np.isfinite(got), np.isfinite(want))


def test_one_late_device_is_realigned_alone_offline_and_live() -> None:
    """The MTi 0.1 s late, the laser on time: the currents and the crowd are delayed to
    the MTi's time, the MTi's own readings are left as they are."""
    res = simulate_cycles(1, seed=3, payload_range=(10000.0, 10000.0), truck_target_kg=None)
    cols0 = dict(res.table.columns)
    term = SensorTimeSkew(delay_s=0.1, crowd_lag_s=-0.1)
    cols = term.transform(cols0)
    t = np.asarray(cols0["time_s"])
    n = int(round(0.1 / float(np.median(np.diff(t)))))
    for name in ("handle_deg", "swing_deg"):
        assert np.array_equal(cols[name], cols0[name])
    for name in ("crowd_m", DRIVE_STREAM[0]):
        assert np.allclose(cols[name][n:], np.asarray(cols0[name])[:-n], equal_nan=True)
        assert np.isnan(cols[name][: n // 2]).all()
    live = term.stream()
    assert live is not None
    out = [live(s) for s in samples_from_table(res.table)]
    for name in ("handle_deg", "crowd_m", DRIVE_STREAM[0]):
        got = np.array([getattr(s, name) for s in out])
        assert np.array_equal(np.isfinite(got), np.isfinite(cols[name]))
        both = np.isfinite(got)
        assert np.allclose(got[both], cols[name][both])
    assert [f["what"] for f in term.findings([], np.zeros(0), np.zeros((0, 0)))] == [
        "MTi stream (handle angle, swing) late against the currents",
        "laser stream (crowd) late against the currents"]


def test_the_slope_moves_the_sheave_by_the_decks_lean_in_the_arm_plane_exactly() -> None:
    """At kappa = 1 (K_H_pitch = K_H) the slope's columns and the rope's own are the rope at
    boom + tilt, not its first-order part: the tilt from the inclinometer's pitch and roll
    (the deck's lean in the arm plane), the curvature of the rope's geometry on K_H."""
    k = _kin(200, seed=3)
    k.pitch, k.roll = np.radians(np.linspace(-9, 9, 200)), np.radians(np.linspace(7, -5, 200))
    slope = Model.from_names(["ground_slope"])
    w = slope.regressor(k)[0]
    p = np.zeros(len(slope.param_names))
    p[[slope.param_names.index("K_H"), slope.param_names.index("K_H_pitch")]] = 1.0
    sp, sr = np.sin(k.pitch), np.sin(k.roll)
    lean = np.arctan2(sp, np.sqrt(1 - sp**2 - sr**2))  # = atan2(sin pitch, cos slope)
    tilted = dataclasses.replace(k, boom=k.boom + lean, pitch=0 * k.pitch, roll=0 * k.roll)
    base = Model.from_names([])
    want = base.regressor(tilted)[0][:, :, base.param_names.index("K_H")]
    assert np.allclose(w @ p, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
    # the first-order part alone is off by the curvature: what the term used to miss
    first = base.regressor(k)[0][:, :, base.param_names.index("K_H")] + w[
        :, :, slope.param_names.index("K_H_pitch")]
    assert np.abs(first - want).max() > 1e-3 * np.abs(want).max()


def _on_trials(machine: Any, effect: str, magnitude: float, seed: int, param: str,
               form: str = "test") -> tuple[ModelParams, float, float]:
    """Base + ``effect`` identified on empty and 8,420 kg trials (seeds ``seed`` and
    ``seed + 1``) on ``machine`` with the effect at ``magnitude``: the params, and the
    term's parameter ``param`` over K_H with its standard error."""
    from shoveld.identify.calibrate import Calibrator
    from shoveld.sim.scenario import simulate_calibration

    trials = [simulate_calibration(load, seed + i, machine=machine,
                                   effects=make_effects({effect: magnitude}, form=form)
                                   ).table for i, load in enumerate((0.0, 8420.0))]
    p = Calibrator(Model.from_names([effect])).fit(trials).params_
    assert p is not None
    k_h = p.get("K_H")
    return p, p.get(param) / k_h, float(p.stderr[p.names.index(param)]) / k_h


def _slope_on_trials(machine: Any, degrees: float, seed: int, form: str = "test"
                     ) -> tuple[ModelParams, float, float]:
    """The slope's params, kappa and its standard error (``_on_trials``)."""
    return _on_trials(machine, "ground_slope", degrees, seed, "K_H_pitch", form)


def test_a_machine_on_a_steep_slope_gives_kappa_one() -> None:
    """Identified on trials on a 9 degree slope, every stroke kept (the thesis's machine,
    its hoist field nominal when lowering too), the slope's kappa is 1 within three
    standard errors and 3 %. The first-order form found 0.81 +- 0.01 here."""
    from shoveld.sim.machine import Machine

    m = Machine.ideal()
    m = dataclasses.replace(m, plant=dataclasses.replace(
        m.plant, hoist_field_lowering_a=m.plant.hoist_field_hoisting_a))
    _, kappa, kappa_se = _slope_on_trials(m, 9.0, 41)
    assert abs(kappa - 1.0) < min(3 * kappa_se, 0.03), (kappa, kappa_se)


@pytest.mark.parametrize("machine", ["thesis", "drawn"])
def test_the_slope_pulls_with_the_current_at_the_field_less_the_sensors_offset(
        machine: str) -> None:
    """kappa is 1 within three standard errors and 3 % where the trials' rope pulls less
    per ampere at times, and the hoist current reads an offset. On the thesis's machine
    the lowering strokes run at a 30 A field (kappa was 0.61 +- 0.05 with the nominal
    field's pull on every row); on a drawn machine (its drive weakening the field when
    lowering fast, its hoist sensors reading 9.6 A high in sum) kappa was 0.938 +- 0.020.
    The ratios come from the fit's own field curve and the offset from its ``i_H0``."""
    from shoveld.sim.machine import Machine

    m = Machine.ideal() if machine == "thesis" else Machine.draw(5_000_000)
    p, kappa, kappa_se = _slope_on_trials(m, 5.5, 5_000_001, form="bench")
    assert abs(kappa - 1.0) < min(3 * kappa_se, 0.03), (kappa, kappa_se)
    v = p.as_dict()
    h = p.hyper["ground_slope"]
    assert h["pull_offset_a"] == pytest.approx(v["i_H0"], abs=1.0)
    drive = p.hyper["hoist_drive"]
    assert len(h["pull_ratios"]) == len({drive["field_nominal_a"], *drive["field_knots_a"]}) > 1
    low = min(drive["field_knots_a"])
    assert h["pull_ratios"][0] == pytest.approx(v[f"K_H_f{low:g}"] / v["K_H"], rel=0.02)


def _boom_drop_on_trials(machine: Any, degrees: float, seed: int
                         ) -> tuple[float, float, float]:
    """The boom's drop at the term's reference current and pose (deg), its standard
    error and the simulated truth, on trials whose boom drops ``degrees`` at 1 MN at
    that pose (``_on_trials``): the drop at the pull the reference current gives at the
    fit's nominal field."""
    p, sag, sag_se = _on_trials(machine, "boom_suspension_spring", degrees, seed, "K_H_sag")
    ref_a = float(BoomSuspensionSpring.defaults["ref_a"])
    truth = BoomSuspensionSpringEffect(degrees).drop_deg_at(machine.k_h_nominal(p) * ref_a)
    return math.degrees(sag), math.degrees(sag_se), truth


def test_the_boom_sags_with_the_pull_and_the_pose_whatever_field_lowering_runs_at() -> None:
    """The thesis's machine, its boom dropping 2.86 deg at 1 MN of rope pull with the
    handle level and the bail 8.5 m out (2.45 deg at 500 A): the drop identified on its
    trials is that, within three standard errors and 10 %, whether its lowering strokes
    run at a 30 A field (an ampere pulling 0.6 of the nominal field's) or at the nominal
    one, and the two agree within three standard errors and 5 %: 2.46 +- 0.22 and 2.49
    +- 0.22 deg. With the current as read in place of the
    rope's pull the first was 0.62; with the pull, but one drop per newton at every pose
    (the machine's follows the bail rope's moment about the boom foot), 1.89 +- 0.21 and
    1.95 +- 0.21."""
    from shoveld.sim.machine import Machine

    thesis = Machine.ideal()
    nominal = dataclasses.replace(thesis, plant=dataclasses.replace(
        thesis.plant, hoist_field_lowering_a=thesis.plant.hoist_field_hoisting_a))
    runs = [_boom_drop_on_trials(m, 2.861, 5_000_001) for m in (thesis, nominal)]
    for drop, se, truth in runs:
        assert abs(drop - truth) < min(3 * se, 0.10 * truth), (drop, se, truth)
    (weak, weak_se, _), (even, even_se, _) = runs
    # and the two fields agree with each other, as before the pose
    assert abs(weak - even) < min(3 * math.hypot(weak_se, even_se), 0.05 * even), (
        weak, weak_se, even, even_se)


def test_the_swing_radius_is_found_where_the_trials_do_not_swing() -> None:
    """A realistic machine whose trials never swing, but whose swing angle's noise,
    differentiated, passes 0.1 rad/s once: the swing's radius needs the verified passes,
    and on them the search finds the true 5.59 m within two of its standard errors and
    0.1 m. Before 2026-11-28 the trials alone were taken (their largest swing rate
    passed the threshold) and the radius came out 0.0 m."""
    from shoveld.diagnose.data import DataSet
    from shoveld.diagnose.fit import SWING_EXCITED_RAD_S, fit, needs_operation
    from shoveld.sim.machine import Machine

    seed, r0 = 7001, 5.586  # a machine and a radius drawn for the bench (notes in docs)
    trials, measured, _ = session({"swing_centrifugal": r0}, 1000 * seed, form="bench",
                                  machine=Machine.draw(1000 * seed))
    ds = DataSet(trials, measured)
    peak = max(float(np.nanmax(np.abs(f.kin.swing_rate)))
               for f in ds.calib_files(Model.from_names([])))
    assert peak > SWING_EXCITED_RAD_S  # the noise's one spike
    model = Model.from_names(["swing_centrifugal"])
    assert needs_operation(model, ds)
    p = fit(ds, ["swing_centrifugal"], {}, {q.index for q in ds.passes if q.verified})
    term = p.model().terms[-1]
    assert isinstance(term, SwingCentrifugal)
    (what, unit, value, std), = term.searched()
    assert unit == "m" and value == p.hyper["swing_centrifugal"]["R0_m"]
    assert abs(value - r0) <= min(2 * std, 0.1), (value, std)


def test_the_delays_standard_errors_are_the_blocks_scatter_through_the_curvature() -> None:
    """Blocks whose own best delays scatter: block b's share of the objective is
    w (k - c_b)^2 + v (k + j - e_b)^2, so the MTi's best delay is the mean of the c_b and
    the laser's (k + j) the mean of the e_b. The sandwich must give the standard errors
    of those means (the scatter over the number of blocks), exactly, for a quadratic."""
    rng = np.random.default_rng(5)
    n, w, v = 40, 3.0, 0.5
    c, e = rng.normal(2.0, 3.0, n), rng.normal(-1.0, 7.0, n)

    def share(b: int, kj: tuple[int, int]) -> float:
        k, j = kj
        return w * (k - c[b]) ** 2 + v * (k + j - e[b]) ** 2

    parts: dict[tuple[int, int], dict[int, float]] = {}

    def objective(kj: tuple[int, int]) -> float:
        parts[kj] = {b: share(b, kj) for b in range(n)}
        return sum(parts[kj].values())

    k0 = round(float(c.mean()))
    best = (k0, round(float(e.mean())) - k0)
    s_mti, s_laser = _delay_errors(best, objective, parts, lambda k, j: True,
                                   {"delay_s", "crowd_lag_s"})
    assert s_mti == pytest.approx(np.std(c, ddof=1) / math.sqrt(n), rel=1e-9)
    assert s_laser == pytest.approx(np.std(e, ddof=1) / math.sqrt(n), rel=1e-9)
    # the laser alone searched (the MTi's delay given): its error is the same; a flat
    # objective, or a neighbour beyond the bounds, has none
    assert _delay_errors(best, objective, parts, lambda k, j: True, {"crowd_lag_s"})[1] == (
        pytest.approx(s_laser, rel=1e-9))
    assert math.isnan(_delay_errors(best, lambda kj: 1.0, parts, lambda k, j: True,
                                    {"delay_s"})[0])
    assert math.isnan(_delay_errors(best, objective, parts, lambda k, j: k <= k0,
                                    {"delay_s", "crowd_lag_s"})[0])


def test_a_searched_values_standard_error_is_the_blocks_scatter_at_the_vertex() -> None:
    """Blocks whose own best values c_b scatter, block b's share of the profile
    w (x - c_b)^2: the minimum is the mean of the c_b, and from three points a whole
    step away from it the parabola must give that mean and the standard error of the
    mean, exactly (each block's gradient taken at the vertex, not at the centre)."""
    rng = np.random.default_rng(11)
    n, w, step = 30, 2.0, 1.0
    c = rng.normal(4.4, 0.5, n)
    x0 = float(c.mean()) + 0.9  # the equation-error search's miss
    xs = (x0, x0 + step, x0 - step)
    parts = [{b: w * (x - c[b]) ** 2 for b in range(n)} for x in xs]
    s = [sum(p.values()) for p in parts]
    dx, std = _parabola(step, s, parts)
    assert x0 + dx == pytest.approx(c.mean(), abs=1e-9)
    assert std == pytest.approx(np.std(c, ddof=1) / math.sqrt(n), rel=1e-9)
    # no curvature: no minimum, no error
    assert all(math.isnan(v) for v in _parabola(step, [1.0, 1.0, 1.0], parts))


@pytest.mark.parametrize("name", sorted(EFFECT_TERMS))
def test_every_model_error_belongs_to_a_value_the_term_reports(name: str) -> None:
    """A model error is looked up by its value's wording: one that matches none would be
    left out of the reported uncertainty without a word."""
    term = TERMS[name]()
    assert isinstance(term, ExtensionTerm)
    words = [q[0] for q in term.quantities()] + [q[0] for q in term.searched()]
    assert set(term.model_error) <= set(words)
    n = len(Model.from_names([name]).param_names)
    for f in term.findings(Model.from_names([name]).param_names, np.ones(n), np.eye(n) * 1e-6):
        m = term.error_of(f["what"])
        assert f["std"] == pytest.approx(math.hypot(f["std_fit"], m))


def test_the_boom_drops_model_error_grows_with_the_reference_current() -> None:
    """The boom's drop is reported at the term's reference current; its model error,
    measured at 500 A, is a drop too: at 1,000 A it is twice as large."""
    at_500, at_1000 = BoomSuspensionSpring(), BoomSuspensionSpring(ref_a=1000.0)
    (w500, _, _), = at_500.quantities()
    (w1000, _, _), = at_1000.quantities()
    assert w1000 != w500 and at_500.error_of(w500) > 0
    assert at_1000.error_of(w1000) == pytest.approx(2 * at_500.error_of(w500))


def test_params_file_records_terms_and_hyper(tmp_path: Path) -> None:
    model = Model.from_names(["sensor_time_skew", "swing_centrifugal"],
                             {"sensor_time_skew": {"delay_s": 0.08},
                              "swing_centrifugal": {"R0_m": 3.7}})
    n = len(model.param_names)
    p = ModelParams(terms=model.term_names, names=model.param_names,
                    values=np.arange(1.0, n + 1), stderr=np.full(n, 0.1), cov=np.eye(n) * 0.01,
                    noise={"handle": 1.0, "crowd": 1.0},
                    hyper={t.name: dict(t.hyper) for t in model.terms if t.hyper})
    save_params(tmp_path / "x.toml", p)
    q = load_params(tmp_path / "x.toml")
    assert q.terms == p.terms
    assert q.hyper["sensor_time_skew"]["delay_s"] == 0.08
    m2 = q.model()
    skew = [t for t in m2.terms if t.name == "sensor_time_skew"][0]
    assert isinstance(skew, SensorTimeSkew)
    assert skew.hyper["delay_s"] == 0.08 and "delay_s" in skew.given
    k = _kin()
    assert np.allclose(m2.regressor(k)[0], model.regressor(k)[0])


def test_a_boom_identified_before_the_pose_keeps_its_form_and_a_bad_pose_is_refused(
        tmp_path: Path) -> None:
    """A params file whose boom term has no ``moment`` (written before the twentieth
    session) was identified with one drop per newton at every pose: it loads in that
    form (its columns those of ``moment = "none"``, its value worded without a pose and
    with that form's model error), while a new file keeps the bail rope's moment; an
    unknown form or an impossible reference pose is refused with a line naming the file
    and the key."""
    from shoveld.model.params import ParamsFileError

    k = _kin()
    k = dataclasses.replace(k, i_h_est=np.linspace(-900.0, 900.0, len(k)))
    pose = Model.from_names(["boom_suspension_spring"])
    n = len(pose.param_names)

    def written(hyper: dict[str, Any]) -> Any:
        p = ModelParams(terms=pose.term_names, names=pose.param_names,
                        values=np.arange(1.0, n + 1), stderr=np.full(n, 0.1),
                        cov=np.eye(n) * 0.01, noise={"handle": 1.0, "crowd": 1.0},
                        hyper={"boom_suspension_spring": hyper})
        save_params(tmp_path / "x.toml", p)
        return load_params(tmp_path / "x.toml")

    new = written(dict(pose.terms[-1].hyper)).model()
    assert np.array_equal(new.regressor(k)[0], pose.regressor(k)[0])
    old = written({"ref_a": 500.0}).model()
    flat = Model.from_names(["boom_suspension_spring"], {"boom_suspension_spring":
                                                        {"moment": "none"}})
    assert np.array_equal(old.regressor(k)[0], flat.regressor(k)[0])
    assert not np.allclose(old.regressor(k)[0], new.regressor(k)[0])
    (what, _, _), = old.terms[-1].quantities()
    assert what == "boom point drop at 500 A of hoist current"
    assert old.terms[-1].error_of(what) == 0.36
    written(dict(pose.terms[-1].hyper))
    text = (tmp_path / "x.toml").read_text()
    for good, bad, key in (('moment = "bail"', 'moment = "up"',
                            "moment: expected 'bail' or 'none'"),
                           ("ref_d_m = 8.5", "ref_d_m = 0.0", "ref_d_m in")):
        assert good in text
        (tmp_path / "y.toml").write_text(text.replace(good, bad))
        with pytest.raises(ParamsFileError, match=rf"y\.toml: hyper\.boom_suspension_spring"
                                                  rf"\.?.*{key}"):
            load_params(tmp_path / "y.toml")


def test_the_saturation_knee_sits_at_the_median_hoist_current_and_bends_the_pull() -> None:
    """The knee is a spline knot placed at the median of the data's hoist current (not
    searched on the residual); below it the term adds nothing, above it it takes a
    fixed share of every further ampere."""
    from types import SimpleNamespace

    i1 = np.array([50.0, 100.0, 150.0, 200.0, np.nan])
    tables = [SimpleNamespace(columns={"hoist1_a": i1, "hoist2_a": i1 + 10.0}),
              SimpleNamespace(columns={"hoist1_a": -i1, "hoist2_a": -i1})]
    term = CurrentSaturation()
    assert term.for_data(tables) is term
    assert term.h("knee_a") == np.median([110, 210, 310, 410, 100, 200, 300, 400])
    given = CurrentSaturation(knee_a=333.0)
    given.for_data(tables)
    assert given.h("knee_a") == 333.0

    k = _kin(200)
    k = dataclasses.replace(k, i_h_est=np.linspace(-600.0, 600.0, 200))
    assert k.i_h_est is not None
    u_th, _ = _unit_hoist(k)
    col = CurrentSaturation(knee_a=250.0).columns(k)[:, 0, 0] / -u_th
    # five rounding widths (20 A) from the knee the hinge is within 20 ln(1 + e^-5) A
    low = np.abs(k.i_h_est) < 150.0
    high = k.i_h_est > 350.0
    assert np.all(np.abs(col[low]) < 0.14)
    assert np.allclose(col[high], k.i_h_est[high] - 250.0, atol=0.14)
    assert np.allclose(col[::-1], -col)
