"""The engine's per-tick fast paths against the general paths they stand for, bit for bit.

``Engine.step`` steps its three joint filters in one call (``update_joints``), pushes the
fixed-lag window with its NaN test done (``push_known``), asks the phase machine with
comparisons for ``abs`` and multiplies by ``math.radians``'s and ``math.degrees``'s
factors; a payload block stacks its pairs with ``pair``. Each must give exactly what the
general path gives, including after gaps, NaN and restarts, or the passes move.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from shoveld.cycle.phases import DIG, DUMP, IDLE, LIFT, RETURN, SWING, PhaseConfig, PhaseMachine
from shoveld.engine.loop import _DEG, _RAD
from shoveld.kinematics.causal import CROWD, HANDLE, JointFilter, update_joints
from shoveld.kinematics.causal import SWING as SWING_JOINT
from shoveld.kinematics.fixed_lag import FixedLagSavgol
from shoveld.model.terms import pair


def bits(xs: tuple[float, ...] | list[float]) -> bytes:
    """The floats' bytes: NaN equals NaN, and -0.0 differs from 0.0."""
    return struct.pack(f"{len(xs)}d", *xs)


def stream(seed: int, n: int = 8000) -> list[tuple[float, float, float, float]]:
    """Ticks (t, handle, crowd, swing) with NaN runs per joint, skipped ticks and a long
    dropout (a filter coasts out and restarts), and jittered times."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    out: list[tuple[float, float, float, float]] = []
    k = 0
    while len(out) < n:
        k += 1 + (rng.random() < 0.001) * int(rng.integers(1, 4))  # skipped ticks
        if 1500 < k < 1570:  # a dropout longer than max_coast_s for the crowd only
            z_d = math.nan
        else:
            z_d = 1.5 + 0.3 * math.sin(0.01 * k) + rng.normal(0, 0.002)
        t = k * dt + (rng.normal(0, 1e-5) if rng.random() < 0.002 else 0.0)
        z = [0.4 * math.sin(0.003 * k) + rng.normal(0, 5e-4), z_d,
             0.8 * math.sin(0.002 * k) + rng.normal(0, 2e-3)]
        for j in range(3):
            if rng.random() < 0.0005:
                z[j] = math.nan
        out.append((t, z[0], z[1], z[2]))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_update_joints_is_three_updates(seed: int) -> None:
    dt = 0.01
    ref = [JointFilter(c, dt) for c in (HANDLE, CROWD, SWING_JOINT)]
    got = [JointFilter(c, dt) for c in (HANDLE, CROWD, SWING_JOINT)]
    fast = 0
    for t, za, zb, zc in stream(seed):
        want = ref[0].update(t, za) + ref[1].update(t, zb) + ref[2].update(t, zc)
        steady = all(f._steady is not None for f in got)
        have = update_joints(got[0], got[1], got[2], t, za, zb, zc)
        fast += steady and za == za and zb == zb and zc == zc
        assert bits(have) == bits(want), t
        for r, g in zip(ref, got, strict=True):
            assert bits(list(r.state())) == bits(list(g.state())) and r._last_t == g._last_t
    assert fast > 3000  # the fast path did run (most ticks)


def test_push_known_is_push_tag() -> None:
    rng = np.random.default_rng(5)
    a: FixedLagSavgol[int] = FixedLagSavgol(0.41, 0.01, 3, 3)
    b: FixedLagSavgol[int] = FixedLagSavgol(0.41, 0.01, 3, 3)
    k = 0
    for i in range(3000):
        k += 1 + (rng.random() < 0.02) * int(rng.integers(1, 12))
        t = k * 0.01
        v = [float(x) for x in rng.normal(size=3)]
        if rng.random() < 0.05:
            v[int(rng.integers(0, 2))] = math.nan
        for _ in range(a.gap(t)):
            assert a.push_hole() == b.push_hole()
        vals = (v[0], v[1], v[2])
        ta = a.push_tag(t, vals, i)
        tb = b.push_known(t, vals, i, v[0] != v[0] or v[1] != v[1])
        assert ta == tb
        if ta is not None:
            assert np.array_equal(a.derivatives(), b.derivatives(), equal_nan=True)


def old_update(m: PhaseMachine, t: float, th: float, thd: float, sw: float,
               cr: float = 0.0) -> int:
    """The phase machine's update before the fast path (``abs`` calls, all eager)."""
    c = m.cfg
    if th != th or thd != thd or sw != sw:
        return m.phase
    moving = abs(thd) > c.idle_rate_deg_s or abs(sw) > c.idle_swing_deg_s \
        or abs(cr) > c.idle_crowd_m_s
    if moving:
        m._still_since = None
    elif m._still_since is None:
        m._still_since = t
    rising = th < c.tuck_deg and thd > c.rise_deg_s and abs(sw) < c.swing_on_deg_s
    p = m.phase
    if p in (IDLE, RETURN):
        if rising:
            m._enter(DIG, t)
        elif p == RETURN and m._still_since is not None and t - m._still_since > c.idle_hold_s:
            m._enter(IDLE, t)
    elif p == DIG:
        if t - m.since >= c.min_dig_s and (th > c.dig_exit_deg or abs(sw) > c.swing_on_deg_s):
            m._enter(LIFT, t)
    elif p == LIFT:
        if abs(sw) > c.swing_on_deg_s:
            m._swing_dir = math.copysign(1.0, sw)
            m._enter(SWING, t)
    elif p == SWING:
        if abs(sw) < c.swing_off_deg_s:
            if m._slow_since is None:
                m._slow_since = t
            elif t - m._slow_since >= c.stop_hold_s:
                m._enter(DUMP, t)
        else:
            m._slow_since = None
    elif p == DUMP:
        if sw * m._swing_dir < -c.swing_on_deg_s or rising or thd < -4 * c.rise_deg_s:
            m._enter(RETURN, t)
    if p not in (IDLE, DIG) and m._still_since is not None \
            and t - m._still_since > c.idle_hold_s:
        m._enter(IDLE, t)
    return m.phase


@pytest.mark.parametrize("cfg", [PhaseConfig(), PhaseConfig(idle_hold_s=0.5, min_dig_s=0.2,
                                                            stop_hold_s=0.05)])
def test_phase_machine_is_the_abs_form(cfg: PhaseConfig) -> None:
    rng = np.random.default_rng(11)
    ref, got = PhaseMachine(cfg), PhaseMachine(cfg)
    seen = set()
    th = thd = sw = cr = 0.0
    for i in range(40000):
        t = i * 0.01
        if rng.random() < 0.05:  # held a while, so that the holds and dwells elapse
            # values around every threshold, both signs, exact thresholds, zeros, NaN
            th = float(rng.choice([-40.0, -25.0, -10.0, -4.0, 0.0, 5.0])) + rng.normal(0, 3)
            thd = float(rng.choice([0.0, 1.5, -1.5, 3.0, -7.0])) * float(rng.random() < 0.7)
            sw = float(rng.choice([0.0, 1.5, -1.5, 3.0, -3.0, 4.0, -4.0, 10.0, -10.0]))
            cr = float(rng.choice([0.0, 0.08, -0.08, 0.2, math.nan]))
            if rng.random() < 0.5:
                thd += rng.normal(0, 0.5)
                sw += rng.normal(0, 0.3)
            if rng.random() < 0.05:
                th = math.nan
        args = (t, th, thd, sw, cr)
        assert got.update(*args) == old_update(ref, *args), i
        assert (got.since, got._slow_since, got._still_since, got._swing_dir) == \
            (ref.since, ref._slow_since, ref._still_since, ref._swing_dir)
        seen.add(got.phase)
    assert seen == {IDLE, DIG, LIFT, SWING, DUMP, RETURN}


def test_the_angle_factors_are_radians_and_degrees() -> None:
    rng = np.random.default_rng(2)
    xs = [float(x) for x in rng.uniform(-720, 720, 20000)] + [
        float(x) for x in rng.normal(0, 1e-3, 20000)] + [0.0, -0.0, math.inf, -math.inf,
                                                         5e-324, 1e308, math.nan]
    assert bits([x * _RAD for x in xs]) == bits([math.radians(x) for x in xs])
    assert bits([x * _DEG for x in xs]) == bits([math.degrees(x) for x in xs])


@pytest.mark.parametrize("shape,axis", [((10,), -1), ((1,), -1), ((10,), 1), ((10, 4), 1),
                                        ((0,), -1)])
def test_pair_is_np_stack(shape: tuple[int, ...], axis: int) -> None:
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=shape), rng.normal(size=shape)
    x.flat[0:1] = np.nan
    got, want = pair(x, y, axis), np.stack([x, y], axis=axis)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert got.flags.c_contiguous and want.flags.c_contiguous
    assert got.tobytes() == want.tobytes()
    # views (non-contiguous inputs), other dtypes and shapes: the same as np.stack too
    z = rng.normal(size=(2,) + shape)[:, ...][0]
    for a, b in ((z, y), (x.astype(np.float32), y), (x, y.astype(int))):
        assert pair(a, b, axis).tobytes() == np.stack([a, b], axis=axis).tobytes()
        assert pair(a, b, axis).dtype == np.stack([a, b], axis=axis).dtype


def test_jacobian_of_a_float_payload_is_the_broadcast_one() -> None:
    """``CurrentEquations.jacobian`` fills an array for a Python float payload (the
    engine's) instead of ``np.broadcast_to``: the same bits as the array path."""
    from pathlib import Path

    from shoveld.model.kin import Kinematics
    from shoveld.model.output import CurrentEquations
    from shoveld.model.params import load_params

    params = load_params(Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures"
                         / "daemon-e2e" / "params.toml")
    rng = np.random.default_rng(8)
    n = 10
    u = [rng.uniform(lo, hi, n) for lo, hi in ((-0.6, 0.6), (-0.5, 0.5), (-2, 2), (1.0, 2.5),
                                               (-0.4, 0.4), (-1, 1), (200, 900), (-80, 80),
                                               (55, 75))]
    z = np.zeros(n)
    k = Kinematics(t=np.arange(n) * 0.01, th=u[0], thd=u[1], thdd=u[2], d=u[3], dd=u[4],
                   ddd=u[5], boom=np.full(n, np.radians(45.0)), i_h=u[6], i_c=u[7],
                   i_hf=u[8], swing=z, swing_rate=z, swing_acc=z, roll=z, pitch=z)
    ce = CurrentEquations(params.model(), k)
    for m in (0.0, -0.0, 31014.3, 1e-300):
        got = ce.jacobian(params.values, m)
        want = ce.jacobian(params.values, np.full(n, m))
        assert got.shape == want.shape and got.tobytes() == want.tobytes()
