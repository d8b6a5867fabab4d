"""The engine: one sample in, phase, live payload, finished passes and trucks out.

This is the only implementation of the payload pipeline. ``shoveld estimate``
feeds it rows of a table; the daemon feeds it samples assembled from the
drivers at each tick. Phases follow the causal Kalman joint filters (no delay);
the payload equations are evaluated half a smoothing window late with zero-phase
rates (``shoveld.kinematics.fixed_lag``), which removes the filter-lag bias.
"""

from __future__ import annotations

import logging
import math
import statistics
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from shoveld.cycle.phases import (
    DIG,
    DUMP,
    ESTIMATING,
    IDLE,
    LIFT,
    PHASES,
    RETURN,
    SWING,
    PhaseConfig,
    PhaseMachine,
)
from shoveld.kinematics import (
    DEFAULT_POLYORDER,
    LEGACY_POLYORDER,
    LEGACY_WINDOW_S,
    PAYLOAD_POLYORDER,
)
from shoveld.kinematics.causal import CROWD, HANDLE, JointFilter, update_joints
from shoveld.kinematics.causal import SWING as SWING_JOINT
from shoveld.kinematics.fixed_lag import FixedLagSavgol
from shoveld.model.kin import Kinematics
from shoveld.model.output import CurrentEquations, current_sigma
from shoveld.model.params import ModelParams
from shoveld.payload.misfit import MISFIT_RECENT, MISFIT_WARN, round_misfit
from shoveld.payload.rls import PayloadRls, RlsConfig
from shoveld.payload.trucks import Truck
from shoveld.sample import CROWD_TARGET_CHANGED, Sample
from shoveld.words import n_of

log = logging.getLogger(__name__)

EMPTY_USE = 3
"""A sample's ``use`` on a return: the empty dipper's (2 and 1: a pass's, settled and in
its settle time; 0: none)."""
EMPTY_S = 4.0
"""Seconds of each return weighed, after its settle time: a return through a truck
exchange lasts much longer, and a few seconds already weigh the empty dipper to about
a tenth of ``empty_warn_kg``."""
EMPTY_EVERY_S = 0.04
"""One sample in this many seconds is weighed on a return (every fourth at 100 Hz): the
check needs no more, and each weighed sample costs the loop a fit of its rates."""
EMPTY_BATCH = round(EMPTY_S / EMPTY_EVERY_S) + 1
"""Samples per update of the empty dipper's filter: a whole return in one block, as
nothing is shown live from it (a block's cost is mostly per block, not per row)."""


def _now_and_then(k: int) -> bool:
    """Whether the k-th warning of a kind is logged: the first, the tenth and every
    hundredth (a machine that misfits, or weighs its empty dipper wrong, does so all
    shift; the counts are in health)."""
    return k in (1, 10) or k % 100 == 0


_all = np.logical_and.reduce
_isfinite = np.isfinite
_RAD = math.pi / 180.0
"""math.radians's factor (CPython's ``degToRad``): ``x * _RAD`` is ``math.radians(x)``."""
_DEG = 180.0 / math.pi
"""math.degrees's factor (``radToDeg``): ``x * _DEG`` is ``math.degrees(x)``."""

FOLD_BLOCKS = 64
"""Payload blocks kept for the filter with the settle time before they are folded into
it: about 6 s of lift and swing at 100 Hz, so a long pass holds a bounded memory."""

NEEDED = ("handle_deg", "crowd_m", "hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a")
"""Signals without which a payload update is not made."""


@dataclass(frozen=True)
class CrowdDoubt:
    """The crowd's laser lost the handle (a gap of ``crowd_gap_s``, a change of target):
    until a pass fits the machine as its passes did before, the laser may be reading
    something else on the handle, which only the pass's misfit can show."""

    what: str
    """What happened, as the refused pass's reason says it ("had no reading for 2.0 s")."""
    t: float
    """When (engine seconds)."""
    limit: float
    """The misfit above which a pass is not weighed while the doubt lasts."""
    usual: float
    """The machine's usual misfit it was set from (the median of the last passes')."""
    weight: float
    """How bad the cause is: infinite for a change of target, else the gap's seconds."""


def doubt_limit(usual: float, cfg: EngineConfig) -> float:
    """The misfit above which a pass is not weighed while the crowd is in doubt, for a
    machine whose usual misfit is ``usual`` (``bench/pass_misfit.py`` judges by it too)."""
    return max(cfg.misfit_warn, cfg.doubt_factor * usual)


@dataclass(frozen=True)
class EngineConfig:
    """Per-site settings of the estimator."""

    rate_hz: float = 50.0
    truck_target_kg: float = 136000.0
    truck_gap_s: float = 20.0
    """A pause this long without digging means the truck was exchanged."""
    warmup_s: float = 1.0
    """The joint filters' start-up transient: no phase changes before it has passed."""
    payload_rates: str = "fixed_lag"
    """'fixed_lag' (zero-phase, half a window late) or 'kalman' (causal, biased by lag);
    kept for bench/kinematics_tradeoff.py, which measures the difference."""
    window_s: float | None = None
    """Zero-phase window of the payload equations; None: the one the params record for
    them (:func:`smoothing`)."""
    polyorder: int | None = None
    """Order of that Savitzky-Golay fit; None: as the params record."""
    batch: int = 10
    """Samples per payload-filter update (one model evaluation and one filter update
    per block; the live payload moves in steps of this many ticks)."""
    settle_s: float = 0.4
    """Samples this soon after leaving the bank may still feel it (bank contact fades):
    they count only if they agree with the rest of the pass (``settle_test_z``)."""
    settle_test_z: float = 2.0
    """The settle time's samples are kept in a pass when its payload with them and
    without them differ by at most this many standard errors of that difference (a
    Hausman test: with no bank contact the estimate with them is the better one, so
    the difference's variance is the difference of the two variances); 0: never kept,
    as before 2026-11-27 (docs/engine.md, "The settle time, tested")."""
    min_samples: int = 40
    """A pass with fewer valid payload updates is reported invalid."""
    min_crowd_travel_m: float = 0.25
    """A pass whose crowd moved less than this from its dig's start to its dump is
    reported invalid: a dig crowds the dipper into the bank (the simulator's passes
    travel 2.3-3.5 m; the handle's stroke is 6-10.8 m), so a crowd that stands still
    is a laser measuring something else (lodged in its beam, taken between passes) or
    stuck. 0: no such test."""
    misfit_warn: float = MISFIT_WARN
    """A pass whose misfit is above this is logged as a warning, and still weighed
    (:data:`shoveld.payload.misfit.MISFIT_WARN`, where the figures are), unless the crowd
    is in doubt (:class:`CrowdDoubt`), where this is the least level of refusal."""
    empty_warn_kg: float = 500.0
    """The empty dipper weighed on its returns (:class:`EmptyCheck`): when the median of
    the last ``empty_returns`` is further than this from zero, the daemon warns that the
    dipper carries material back, that the machine has changed since its calibration, or
    that the model lacks something it does.
    ``bench/pass_misfit.py --drift 3`` measures the returns of realistic simulated
    machines unchanged and changed since their calibration (docs/engine.md, "The empty
    dipper on its returns"). 0: no check."""
    empty_returns: int = 5
    """Returns the empty check takes the median of."""
    crowd_gap_s: float = 0.2
    """The crowd's reading missing this long (the laser silent, reconnected, or seeing no
    target) leaves what it reads next in doubt (:class:`CrowdDoubt`): the handle moves up
    to 3 m/s, so after a gap the driver cannot tell something on the handle within that
    reach from the handle itself (docs/drivers-ar4000.md, "A reconnect keeps the handle's
    reach")."""
    doubt_factor: float = 10.0
    """While the crowd is in doubt, a pass whose misfit is above this many times the
    machine's usual (the median of the last passes' before the doubt, and at least
    ``misfit_warn``) is not weighed: something on the handle put the committed capture's
    passes at 26-578 where they had 0.84, a swing the model lacks spreads one machine's
    passes over 4.6-59 around a median of 18 (docs/engine.md, "A crowd in doubt"). 0: no
    doubt, every pass weighed."""
    hoist_field_nominal_a: float = 70.0
    weak_field_fraction: float = 0.97
    phases: PhaseConfig = field(default_factory=PhaseConfig)
    rls: RlsConfig = field(default_factory=RlsConfig)

    RANGES: ClassVar[dict[str, dict[str, float | bool]]] = {
        "warmup_s": {"lo": 0.0}, "batch": {"lo": 1}, "settle_s": {"lo": 0.0},
        "settle_test_z": {"lo": 0.0}, "min_samples": {"lo": 1},
        "min_crowd_travel_m": {"lo": 0.0}, "misfit_warn": {"lo": 0.0},
        "empty_warn_kg": {"lo": 0.0}, "empty_returns": {"lo": 1},
        "crowd_gap_s": {"positive": True}, "doubt_factor": {"lo": 0.0},
        "hoist_field_nominal_a": {"positive": True},
        "weak_field_fraction": {"lo": 0.0, "hi": 1.0}}
    """What the configuration may set each number to (``shoveld.daemon.config``; 0 where
    it switches a check off): a batch of 0 samples, a negative settle time or a crowd
    gap of 0 s (every tick a gap) was taken until 2026-11-30."""


@dataclass(slots=True)
class LiveEstimate:
    time_s: float
    phase: str
    payload_kg: float
    std_kg: float
    valid: bool


@dataclass
class PassResult:
    """A finished pass: final at the dump."""

    index: int
    truck: int
    start_s: float
    end_s: float
    payload_kg: float
    std_kg: float
    samples: int
    valid: bool
    reason: str = ""
    misfit: float = math.nan
    """The pass's residuals' mean square over the size the calibration's noise model gives
    them (``PayloadRls.misfit``: 1 when the model holds; NaN: no sample). Given for
    passes not weighed too: a change of the laser's target, say, shows there."""

    def as_dict(self) -> dict[str, Any]:
        return {"pass": self.index, "truck": self.truck, "start_s": round(self.start_s, 3),
                "end_s": round(self.end_s, 3),
                "payload_kg": None if not self.valid else round(self.payload_kg, 1),
                "std_kg": None if not self.valid else round(self.std_kg, 1),
                "samples": self.samples, "valid": self.valid, "reason": self.reason,
                "misfit": round_misfit(self.misfit)}


@dataclass
class EmptyCheck:
    """The empty dipper weighed on a return, from the dump to the next dig: zero when
    the calibration still fits the machine and nothing stays in the dipper. Not a
    payload: it corrects nothing, it checks."""

    after_pass: int
    """The pass whose dump the return followed."""
    end_s: float
    payload_kg: float
    std_kg: float
    samples: int
    median_kg: float
    """The median of the last ``empty_returns`` checks, this one included."""

    def as_dict(self) -> dict[str, Any]:
        return {"after_pass": self.after_pass, "end_s": round(self.end_s, 3),
                "payload_kg": round(self.payload_kg, 1), "std_kg": round(self.std_kg, 1),
                "samples": self.samples, "median_kg": round(self.median_kg, 1)}


@dataclass
class TruckResult:
    truck: Truck
    closed: bool

    def as_dict(self) -> dict[str, Any]:
        return {**self.truck.as_dict(), "closed": self.closed}


Event = LiveEstimate | PassResult | TruckResult | EmptyCheck


def smoothing(params: ModelParams, cfg: EngineConfig) -> tuple[float, int]:
    """The Savitzky-Golay window and order of the payload equations: as configured, else
    the payload's own as recorded by the calibration (since 2026-11-26), else the
    identification's as recorded, else what unrecorded params were identified with (so
    an older params file estimates as it did)."""
    fit = params.fit or {}
    if "payload_window_s" in fit:
        rec: tuple[float, int] = (float(fit["payload_window_s"]),
                                  int(fit.get("payload_polyorder", PAYLOAD_POLYORDER)))
    elif "window_s" in fit:
        rec = (float(fit["window_s"]), int(fit.get("polyorder", DEFAULT_POLYORDER)))
    else:
        rec = (LEGACY_WINDOW_S, LEGACY_POLYORDER)
    return (cfg.window_s if cfg.window_s is not None else rec[0],
            cfg.polyorder if cfg.polyorder is not None else rec[1])


class Engine:
    """Causal payload pipeline for one shovel."""

    def __init__(self, params: ModelParams, cfg: EngineConfig | None = None,
                 first_pass: int = 1, first_truck: int = 1,
                 truck_passes: list[dict[str, Any]] | None = None) -> None:
        self.cfg = cfg or EngineConfig()
        self.params = params
        self.model = params.model()
        self.p = params.values
        dt = 1.0 / self.cfg.rate_hz
        self.dt = dt
        self.f_th = JointFilter(HANDLE, dt)
        self.f_d = JointFilter(CROWD, dt)
        self.f_sw = JointFilter(SWING_JOINT, dt)
        self.batch: list[tuple[float, ...]] = []
        self._cached: tuple[int, float, float] = (-1, math.nan, math.nan)
        self.uses_field = any(getattr(t, "uses_field_current", False) for t in self.model.terms)
        self.window_s, self.polyorder = smoothing(params, self.cfg)
        self.lagged: FixedLagSavgol[tuple[Sample, int, int] | None] = FixedLagSavgol(
            self.window_s, dt, 3, self.polyorder)
        self.phases = PhaseMachine(self.cfg.phases)
        self.noise = (params.noise["handle"], params.noise["crowd"])
        self.current_noise = params.current_noise
        """The calibration's current-noise model; empty for a params file of the old
        equation-error form, which the filter then runs in its own units."""
        self._hac_lag = round(self.window_s / dt) if self.current_noise else 0
        """Samples the payload's scores are correlated over (the angles' smoothing
        window): the lag of every pass's filter, and of the empty dipper's."""
        self.rls: PayloadRls | None = None
        """The pass's filter over its settled samples (the live estimate's)."""
        self.rls_all: PayloadRls | None = None
        """The same pass with its settle time's samples too (``settle_test_z``), brought
        up to date only now and then (:meth:`_fold`): the live estimate does not need it."""
        self._rows: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]] = []
        """The payload rows (a, b, db/dp, sigma blocks) not yet in ``rls_all``."""
        self._early_rows = 0
        """Rows of the pass's settle time (they come first: a pass without any keeps no
        rows for ``rls_all``)."""
        self.settle_kept = 0
        self.settle_refused = 0
        """Passes whose settle time the test kept and refused: many refusals say the
        bank holds the dipper past the phase machine's exit (``dig_exit_deg``)."""
        self.misfit_high = 0
        """Passes whose misfit was above ``misfit_warn``."""
        self.last_misfit = math.nan
        """The last finished pass's misfit (NaN: none yet, or no sample in it)."""
        self.recent_misfits: deque[bool] = deque(maxlen=MISFIT_RECENT)
        """Whether each of the last passes weighed was above ``misfit_warn``."""
        self.fits: deque[float] = deque(maxlen=MISFIT_RECENT)
        """The misfits of the last passes weighed while the crowd was not in doubt: the
        machine's usual, which a :class:`CrowdDoubt` is judged against."""
        self.crowd_doubt: CrowdDoubt | None = None
        """Set when the crowd's laser lost the handle, cleared by a pass that fits."""
        self.doubt_refused = 0
        """Passes not weighed for a crowd in doubt, since the start."""
        self.doubt_refusing = 0
        """Of those, the passes in a row not weighed for the doubt there is now (health
        names it while it lasts: a gap alone is common, a pass refused is not)."""
        self.doubt_last_misfit = math.nan
        """The misfit of the last pass not weighed for it."""
        self._crowd_t = math.nan
        """The last tick with a crowd reading (NaN: none yet, and a start is no gap;
        minus infinity after :meth:`carry_on`, whose restart is one)."""
        self.rls_empty: PayloadRls | None = None
        """The empty dipper's filter while it returns (:class:`EmptyCheck`)."""
        self.return_start = math.nan
        self._empty_tick = 0
        self._empty_every = max(1, round(EMPTY_EVERY_S / dt))
        self.empty_checks: list[float] = []
        """The last ``empty_returns`` empty-dipper weights, oldest first."""
        self.empty_warned = 0
        """Checks whose median was beyond ``empty_warn_kg``."""
        self.empty_median = math.nan
        """The median of ``empty_checks``."""
        self.pass_index = first_pass - 1
        self._cycle = 0
        """Dig cycles started: tags the lagged samples so none crosses into another cycle
        (a pass number can be reused after an abandoned cycle; this count never is)."""
        self.pass_start = math.nan
        self.dig_end = math.nan
        self.invalid_updates = 0
        self.missed_ticks = 0
        """Ticks missing from the pass's lift and swing (a loop too busy to keep its rate,
        or rows missing from a table), as the fixed-lag rates see them: said with a pass
        left with too few valid samples, as their likely cause."""
        self.target_changed_t: float | None = None
        """When the crowd's laser changed target (:data:`CROWD_TARGET_CHANGED`) in the
        pass in progress, from its dig's start (set and read only while there is one;
        cleared at the next dig): it is not weighed, for its crowd is of two things.
        Between passes a change costs nothing: a bench block of 10-20 s in one pass left
        the passes on either side exact, where counting changes since the last dump lost
        the next pass in 10 of 10 runs (bench/laser_strays.py --in-passes 2)."""
        self._crowd_lo, self._crowd_hi = math.inf, -math.inf
        """The pass's smallest and largest crowd so far (``min_crowd_travel_m``)."""
        self.truck = Truck(first_truck, self.cfg.truck_target_kg, list(truck_passes or []))
        self.last_dump_t = -math.inf
        self.last: LiveEstimate | None = None
        self.t0 = math.nan
        # Terms that re-shape the signals (e.g. re-aligning a late sensor stream) do it
        # causally here, sample by sample, as their transform does offline.
        self.streams = [f for t in self.model.terms
                        if (f := getattr(t, "stream", lambda: None)()) is not None]
        # The settings read at every tick, as plain attributes (one lookup, not two).
        self._warmup_s = self.cfg.warmup_s
        self._settle_s = self.cfg.settle_s
        self._early_use = 1 if self.cfg.settle_test_z > 0 else 0
        self._kalman_rates = self.cfg.payload_rates == "kalman"
        self._crowd_gap_s = self.cfg.crowd_gap_s

    # -- public -----------------------------------------------------------------------
    def step(self, s: Sample) -> list[Event]:
        """Process one sample; return the events it produced (always one LiveEstimate)."""
        if self.streams:
            for f in self.streams:
                s = f(s)
        t = s.time_s
        bad = s.invalid
        # x * _RAD and x * _DEG are math.radians and math.degrees (the same product with
        # the same constant, so the same bits) without a call each
        if bad:
            z_th = math.nan if "handle_deg" in bad else s.handle_deg * _RAD
            z_d = math.nan if "crowd_m" in bad else s.crowd_m
            z_sw = math.nan if "swing_deg" in bad else s.swing_deg * _RAD
            if CROWD_TARGET_CHANGED in bad:
                self._doubt_crowd("took another target", t, math.inf)
                if self.rls is not None:
                    self.target_changed_t = t
        else:
            z_th, z_d, z_sw = s.handle_deg * _RAD, s.crowd_m, s.swing_deg * _RAD
        th, thd, thdd, d, dd, ddd, sw, swd, swdd = update_joints(
            self.f_th, self.f_d, self.f_sw, t, z_th, z_d, z_sw)
        if z_d == z_d:  # a crowd reading, after a gap?
            if t - self._crowd_t > self._crowd_gap_s:  # False for the first (NaN)
                gap = t - self._crowd_t
                self._doubt_crowd(f"had no reading for {gap:.1f} s" if gap < math.inf
                                  else "went unread while the daemon was stopped", t, gap)
            self._crowd_t = t
        if z_d < self._crowd_lo:  # False for NaN
            self._crowd_lo = z_d
        if z_d > self._crowd_hi:
            self._crowd_hi = z_d
        phases = self.phases
        prev = phases.phase
        if self.t0 != self.t0:  # NaN: the first sample
            self.t0 = t
        if t - self.t0 >= self._warmup_s:
            ph = phases.update(t, th * _DEG, thd * _DEG, swd * _DEG, dd)
        else:
            ph = prev
        events: list[Event] = self._transition(prev, ph, t) if ph != prev else []
        valid = False
        estimating = ph == LIFT or ph == SWING  # ph in ESTIMATING
        # which samples the payload may use: 2 settled, 1 in the settle time, 0 none
        use = (0 if not estimating else 2 if t - self.dig_end >= self._settle_s
               else self._early_use)
        # a return weighs the empty dipper (its own filter), from a settle time after
        # the dump on (3: an empty-dipper sample); the batch is kept for it as for a pass
        weighing = estimating
        if ph == RETURN and self.rls_empty is not None:
            weighing = True
            since = t - self.return_start - self._settle_s
            if 0.0 <= since <= EMPTY_S:
                self._empty_tick += 1
                if self._empty_tick % self._empty_every == 0:
                    use = EMPTY_USE
        lag = self.lagged
        if self._kalman_rates:
            if use and (self.rls is not None or self.rls_empty is not None):
                valid = self._update(s, th, d, sw, thd, dd, swd, thdd, ddd, swdd, use)
        else:
            if t - lag.last_t > lag.late:  # ticks the loop skipped: holes in the window
                if estimating:
                    self.missed_ticks += lag.missed(t)
                for _ in range(lag.gap(t)):
                    valid = self._lagged(lag.push_hole(), ph) or valid
            tag = lag.push_known(t, (z_th, z_d, 0.0 if z_sw != z_sw else z_sw),
                                 (s, use, self._cycle), z_th != z_th or z_d != z_d)
            # _lagged's two common answers inline: no centre sample yet, or one that
            # is not used (not settled, or not this cycle's)
            if tag is None:
                if estimating:
                    self.invalid_updates += 1
            elif tag[1] and tag[2] == self._cycle and (self.rls is not None
                                                        or self.rls_empty is not None):
                valid = self._lagged(tag, ph) or valid
        if self.batch and not weighing:
            self._flush()
        rls = self.rls
        if rls is not None and rls.n:
            cached = self._cached
            if cached[0] != rls.n:  # the filter moves only when a block is applied
                cached = self._cached = (rls.n, rls.payload_kg, self._std())
            est = LiveEstimate(t, PHASES[ph], cached[1], cached[2],
                               (valid or not estimating) and self.target_changed_t is None)
        else:
            est = LiveEstimate(t, PHASES[ph], math.nan, math.nan, False)
        self.last = est
        events.append(est)
        return events

    def finish(self) -> list[Event]:
        """End of data: close the current truck if it has passes."""
        if self.truck.passes:
            return [TruckResult(self.truck, closed=True)]
        return []

    def new_truck(self) -> list[Event]:
        """Close the current truck now (operator's button, or a dispatch message)."""
        out: list[Event] = []
        if self.truck.passes:
            out.append(TruckResult(self.truck, closed=True))
            self.truck = Truck(self.truck.index + 1, self.cfg.truck_target_kg)
        return out

    def carry_on(self, misfits: list[float], empties: list[float]) -> None:
        """The checks a former run with the same params left (the pass log's, after a
        restart), oldest first: the passes' misfits judged by this engine's level, and
        the empty dipper's last weights."""
        self.recent_misfits.extend(m > self.cfg.misfit_warn for m in misfits
                                   if math.isfinite(m))
        self.fits.extend(m for m in misfits if math.isfinite(m))
        if self.fits and self._crowd_t != self._crowd_t:
            # the handle went unwatched while the daemon was down: its first reading is
            # in doubt, as after a gap (a start without this machine's usual cannot be)
            self._crowd_t = -math.inf
        checks = self.empty_checks = list(empties)[-max(1, self.cfg.empty_returns):]
        self.empty_median = statistics.median(checks) if checks else math.nan

    def _doubt_crowd(self, what: str, t: float, weight: float) -> None:
        """The crowd's laser lost the handle at ``t``: judge the passes from here against
        the machine's usual misfit, if it has one (a machine with no pass fitted yet
        has nothing to be judged against, and is weighed as before). A doubt already
        there names the worst of its causes (``weight``: a change of target, else the
        longest gap); its level stays, as no pass has fitted since."""
        old = self.crowd_doubt
        if old is not None:
            if weight >= old.weight:
                self.crowd_doubt = replace(old, what=what, t=t, weight=weight)
            return
        if not self.fits or self.cfg.doubt_factor <= 0:
            return
        usual = statistics.median(self.fits)
        self.crowd_doubt = CrowdDoubt(what, t, doubt_limit(usual, self.cfg), usual, weight)

    def _doubt_reason(self, doubt: CrowdDoubt, misfit: float) -> str:
        """Why a pass is not weighed for a crowd in doubt (logged now and then)."""
        self.doubt_refused += 1
        self.doubt_refusing += 1
        self.doubt_last_misfit = misfit
        when = ("in this pass" if doubt.t >= self.pass_start
                else f"{self.pass_start - doubt.t:.0f} s before this pass")
        if _now_and_then(self.doubt_refused):
            log.warning("pass %d not weighed: the crowd laser %s %s, and its misfit %.1f is "
                        "above %.1f (%g times the machine's usual %.2f); %s so far",
                        self.pass_index, doubt.what, when, misfit, doubt.limit,
                        self.cfg.doubt_factor,
                        doubt.usual, n_of(self.doubt_refused, "such pass", "such passes"))
        return (f"the crowd laser may not be on the handle: it {doubt.what} {when}, and the "
                f"pass does not fit the machine since (misfit {misfit:.0f}, its usual "
                f"{doubt.usual:.2f}); something else may be in its beam")

    @property
    def empty_beyond(self) -> bool:
        """Whether the median of the last ``empty_returns`` checks (that many at least) is
        beyond ``empty_warn_kg``: the state health reports, cleared by a median back
        within it."""
        return (len(self.empty_checks) >= self.cfg.empty_returns
                and abs(self.empty_median) > self.cfg.empty_warn_kg)

    # -- internals --------------------------------------------------------------------
    def _transition(self, prev: int, ph: int, t: float) -> list[Event]:
        out: list[Event] = []
        if prev == RETURN and self.rls_empty is not None:
            out.extend(self._finish_empty(t))
        if ph == RETURN and self.rls is None and prev == DUMP and self.cfg.empty_warn_kg > 0:
            # the pass was weighed at its dump: the dipper is empty now
            self.rls_empty = PayloadRls(self.noise, self.dt * self._empty_every, self.cfg.rls,
                                        hac_lag=self._hac_lag // self._empty_every)
            self.return_start = t
            self._empty_tick = 0
            self.batch.clear()
        if ph == DIG:
            if t - self.last_dump_t > self.cfg.truck_gap_s:
                out.extend(self.new_truck())
            self.pass_index += 1
            self._cycle += 1
            self.pass_start = t
            self.rls = PayloadRls(self.noise, self.dt, self.cfg.rls, hac_lag=self._hac_lag)
            self.rls_all = None
            self._rows = []
            self._early_rows = 0
            self._cached = (-1, math.nan, math.nan)
            self.batch.clear()
            self.invalid_updates = 0
            self.missed_ticks = 0
            self.target_changed_t = None
            self._crowd_lo, self._crowd_hi = math.inf, -math.inf
        elif prev == DIG:
            self.dig_end = t
        if ph == DUMP and self.rls is not None:
            self._flush()
            out.extend(self._finish_pass(t))
        if ph == IDLE and prev != IDLE and self.rls is not None and prev in ESTIMATING:
            # the cycle was abandoned before a dump: no pass, and its number goes to the
            # next cycle, so the operator's pass numbers have no gaps
            self.rls = self.rls_all = None
            self._rows = []
            self.pass_index -= 1
        return out

    def _finish_empty(self, t: float) -> list[Event]:
        """The return is over: the empty dipper's weight, if the return had enough
        samples, and a warning when the last returns' median is far from zero."""
        self._flush()
        rls = self.rls_empty
        assert rls is not None
        self.rls_empty = None
        if rls.n < self.cfg.min_samples:
            return []
        kg = rls.payload_kg
        checks = self.empty_checks
        checks.append(kg)
        del checks[:-max(1, self.cfg.empty_returns)]
        # the standard library's median of a few floats: the same number as numpy's,
        # without importing numpy.ma, which np.median does at its first call
        med = self.empty_median = statistics.median(checks)
        if self.empty_beyond:
            self.empty_warned += 1
            k = self.empty_warned
            if _now_and_then(k):
                log.warning("the empty dipper weighs %+.0f kg on its returns (median of the "
                            "last %d; %s): material stays in the dipper, or the machine has "
                            "changed since its calibration (weigh a known load, calibrate "
                            "again), or the model lacks something this machine does in its "
                            "fast returns (shoveld diagnose names it); the passes may be off "
                            "too",
                            med, len(checks), n_of(k, "such check so far",
                                                   "such checks so far"))
        return [EmptyCheck(self.pass_index, t, kg, rls.std_kg, rls.n, med)]

    def _final_filter(self) -> PayloadRls:
        """The pass's filter to report: with the settle time's samples when they agree
        with the settled ones (``settle_test_z``), else without them. Samples that make
        the pass's own std larger, not smaller, are refused too: the test's premise (the
        estimate with them is the better one) does not hold."""
        rls = self.rls
        assert rls is not None
        if not self._early_rows or not rls.n:
            return rls
        self._fold()
        early = self.rls_all
        assert early is not None
        d = rls.payload_kg - early.payload_kg
        v = rls.std_kg ** 2 - early.std_kg ** 2
        z = self.cfg.settle_test_z
        if d * d <= z * z * v:
            self.settle_kept += 1
            return early
        self.settle_refused += 1
        log.info("pass %d: its first %.1f s out of the bank left out (with them the "
                 "payload moves %+.0f kg, %s): the bank may still hold the dipper there; "
                 "%d of %d passes left out so far",
                 self.pass_index, self.cfg.settle_s, -d,
                 f"{abs(d) / math.sqrt(v):.1f} std" if v > 0 else "and is noisier",
                 self.settle_refused, self.settle_refused + self.settle_kept)
        return rls

    def _finish_pass(self, t: float) -> list[Event]:
        rls = self._final_filter()
        travel = self._crowd_hi - self._crowd_lo  # -inf: no crowd at all
        still = 0.0 <= travel < self.cfg.min_crowd_travel_m
        changed = self.target_changed_t
        valid = rls.n >= self.cfg.min_samples and changed is None and not still
        if changed is not None:
            at = changed - self.pass_start
            reason = f"the crowd laser changed target {at:.1f} s into the pass"
        elif rls.n < self.cfg.min_samples:
            reason = (f"only {n_of(rls.n, 'valid sample', 'valid samples')} in lift and "
                      f"swing ({self.invalid_updates} invalid)")
            if self.missed_ticks:
                # the joints' rates need most of a window's ticks: a loop that skips many
                # leaves them no fit, whatever the sensors did (health says "overruns");
                # offline, rows missing from the table do the same. After ": ", as the
                # cab shows a reason's head and the rest where it is touched
                reason += (f": {n_of(self.missed_ticks, 'tick', 'ticks')} missing from "
                           "them (a loop too busy to keep its rate?)")
        elif still:
            reason = (f"the crowd moved {travel:.2f} m in the pass: the laser sees something "
                      "other than the handle, or is stuck")
        else:
            reason = ""
        misfit = self.last_misfit = rls.misfit
        if valid and math.isfinite(misfit):
            doubt = self.crowd_doubt
            if doubt is None:
                self.fits.append(misfit)
            elif misfit > doubt.limit:
                valid = False
                reason = self._doubt_reason(doubt, misfit)
            elif doubt.t <= self.pass_start:
                # a whole pass read since the doubt fits: the laser is on the handle (a
                # pass the doubt came in may have fitted on its readings before it)
                self.crowd_doubt = None
                self.doubt_refusing = 0
                self.fits.append(misfit)
        if valid and math.isfinite(misfit):
            # the weighed passes only: one not weighed says its own cause (a laser that
            # changed target, a crowd in doubt), which "did not fit" would hide
            self.recent_misfits.append(misfit > self.cfg.misfit_warn)
        if misfit > self.cfg.misfit_warn:
            self.misfit_high += 1
            k = self.misfit_high
            if _now_and_then(k):
                log.warning("pass %d: misfit %.1f, the model's residuals %.1f times the "
                            "size the calibration's noise model gives them (%s): the model "
                            "may lack something this machine does (shoveld diagnose names "
                            "it), or a sensor measures something else (the laser on something "
                            "other than the handle); the pass log has every pass's misfit",
                            self.pass_index, misfit, math.sqrt(misfit),
                            n_of(k, "such pass so far", "such passes so far"))
        pr = PassResult(self.pass_index, self.truck.index, self.pass_start, t, rls.payload_kg,
                        self._std(rls), rls.n, valid, reason, misfit)
        self.truck.passes.append(pr.as_dict())
        self.last_dump_t = t
        self.rls = self.rls_all = None
        self._rows = []
        return [pr, TruckResult(self.truck, closed=False)]

    def _lagged(self, tag: tuple[Sample, int, int] | None, ph: int) -> bool:
        """The payload update of the sample the fixed-lag fit has just centred on."""
        if tag is None:
            if ph in ESTIMATING:
                self.invalid_updates += 1
            return False
        s_lag, use, cycle_lag = tag
        if use and cycle_lag == self._cycle and (self.rls is not None
                                                  or self.rls_empty is not None):
            # the fit only where it is used; as Python floats, which the checks and the
            # batch's array take faster than numpy scalars (the same values)
            (th, d, sw), (thd, dd, swd), (thdd, ddd, swdd) = (
                self.lagged.derivatives().tolist())
            return self._update(s_lag, th, d, sw, thd, dd, swd, thdd, ddd, swdd, use)
        return False

    def _update(self, s: Sample, th: float, d: float, sw: float, thd: float, dd: float,
                swd: float, thdd: float, ddd: float, swdd: float, use: int = 2) -> bool:
        """Queue one sample for the payload filter if its inputs are valid (``use`` 1:
        a settle-time sample, for the pass's second filter only)."""
        i_h = s.hoist1_a + s.hoist2_a
        if (not s.invalid.isdisjoint(NEEDED) or math.isnan(i_h) or math.isnan(s.crowd_a)
                or math.isnan(th) or math.isnan(d)):
            self.invalid_updates += 1
            return False
        if not self.uses_field and (
                s.hoist_field_a < self.cfg.weak_field_fraction * self.cfg.hoist_field_nominal_a):
            return False
        boom = s.boom_deg if not math.isnan(s.boom_deg) else 45.0
        roll = 0.0 if math.isnan(s.roll_deg) else s.roll_deg
        pitch = 0.0 if math.isnan(s.pitch_deg) else s.pitch_deg
        self.batch.append((s.time_s, th, thd, thdd, d, dd, ddd, boom, i_h, s.crowd_a,
                           s.hoist_field_a, sw, swd, swdd, roll, pitch, use))
        if len(self.batch) >= (self.cfg.batch if self.rls is not None else EMPTY_BATCH):
            self._flush()
        return True

    def _flush(self) -> None:
        """Evaluate the model once for the queued samples and update the filter."""
        target = self.rls if self.rls is not None else self.rls_empty
        if not self.batch or target is None:
            self.batch.clear()
            return
        c = np.array(self.batch).T
        self.batch.clear()
        k = Kinematics(t=c[0], th=c[1], thd=c[2], thdd=c[3], d=c[4], dd=c[5], ddd=c[6],
                       boom=np.radians(c[7]), i_h=c[8], i_c=c[9], i_hf=c[10], swing=c[11],
                       swing_rate=c[12], swing_acc=c[13], roll=np.radians(c[14]),
                       pitch=np.radians(c[15]))
        m = target.payload_kg if target.n else 0.0
        if self.current_noise:
            # Current units: measured minus predicted current per channel, each sample
            # weighted by its channel's noise at its reading (shoveld.model.output).
            ce = CurrentEquations(self.model, k)
            a, b = ce.payload_equations(self.p)
            sig = current_sigma(self.current_noise, ce, self.p)
            jac = ce.jacobian(self.p, m)
            # the rows' test only when a value is not finite (two ufuncs an array, without
            # the ``all`` methods' Python wrappers: nearly every block is all finite)
            use = c[16]
            if not (_all(_isfinite(a), None) and _all(_isfinite(b), None)):
                ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
                if not ok.all():
                    a, b, sig, jac, use = a[ok], b[ok], sig[ok], jac[ok], use[ok]
            self._apply(use, a, b, -jac, sig)
            return
        w, phi, psi = self.model.regressor(k)
        a = phi + psi @ self.p
        b = -(w @ self.p)
        self._apply(c[16], a, b, -(w + m * psi), None)

    def _apply(self, use: np.ndarray, a: np.ndarray, b: np.ndarray, db_dp: np.ndarray,
               sig: np.ndarray | None) -> None:
        """A block's rows into the pass: the settled ones into the live filter, every one
        (once the pass has a settle time) kept for the filter with the settle time. On a
        return, into the empty dipper's filter."""
        if self.rls is None:
            assert self.rls_empty is not None
            # only the return's own rows: the pass's last ones, half a window late, may
            # still come in a return that began sooner after the dump
            own = use == EMPTY_USE
            if not own.all():
                if not own.any():
                    return
                a, b, db_dp = a[own], b[own], db_dp[own]
                sig = None if sig is None else sig[own]
            self.rls_empty.update(a, b, db_dp, sigma=sig)
            return
        # A pass's rows come in time order, its settle time's first, so a block whose first
        # row is settled is settled throughout (one look, not an array test per block).
        settled = not len(use) or use[0] == 2
        if not settled:
            keep = use == 2
            self._early_rows += len(keep) - int(np.count_nonzero(keep))
        if self._early_rows:
            self._rows.append((a, b, db_dp, sig))
            if len(self._rows) >= FOLD_BLOCKS:
                self._fold()
        if not settled:
            if not keep.any():
                return
            a, b, db_dp = a[keep], b[keep], db_dp[keep]
            sig = None if sig is None else sig[keep]
        self.rls.update(a, b, db_dp, sigma=sig)

    def _fold(self) -> None:
        """The kept rows into ``rls_all`` in one update (the same estimate as block by
        block without forgetting, the default), so they never pile up."""
        if not self._rows:
            return
        if self.rls_all is None:
            assert self.rls is not None
            self.rls_all = PayloadRls(self.noise, self.dt, self.cfg.rls,
                                      hac_lag=self.rls.hac_lag)
        a, b, db_dp, sig = zip(*self._rows, strict=True)
        self.rls_all.update(np.concatenate(a), np.concatenate(b), np.concatenate(db_dp),
                            sigma=None if sig[0] is None else np.concatenate(sig))
        self._rows = []

    def _std(self, rls: PayloadRls | None = None) -> float:
        """Total payload std of a pass's filter (default: the live one): the pass's own
        noise and the calibration's uncertainty."""
        rls = self.rls if rls is None else rls
        assert rls is not None
        return math.hypot(rls.std_kg, rls.param_std_kg(self.params.cov))


def run_engine(samples: Iterable[Sample], engine: Engine) -> Iterator[Event]:
    """Drive an engine over a finite source of samples (offline)."""
    for s in samples:
        yield from engine.step(s)
    yield from engine.finish()
