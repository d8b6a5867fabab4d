"""Measured data prepared once for the whole diagnosis: passes and per-model views.

A *view* is what the identification sees of the data for one model: kinematics
after the model's signal transforms and the samples the model accepts. Views are
cached by what changes them (the transforms' hyper-parameters and whether the
model accepts weak-field samples), so trying nine candidates does not redo the
smoothing of an hour of data nine times.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from shoveld.cycle.offline import label_phases
from shoveld.cycle.phases import DIG, LIFT, SWING
from shoveld.identify.calibrate import ExclusionConfig, FileData, exclusion_masks
from shoveld.kinematics import DEFAULT_POLYORDER, DEFAULT_WINDOW_S
from shoveld.model.model import Model
from shoveld.model.terms import Term
from shoveld.signals.table import SignalsTable

RATED_PAYLOAD_KG = 35000.0
"""Rated dipper payload of the trial machine (model-notes)."""
SETTLE_S = 0.4
"""As the engine: samples this soon after leaving the bank are not used."""


@dataclass
class Pass:
    """One dig-lift-swing-dump cycle of the measured data."""

    index: int
    table: int
    start_s: float
    end_s: float
    eval_idx: np.ndarray
    """Sample indices (into its table) of lift and swing after the settle time."""
    payload_kg: float
    """Scale-verified payload, NaN when not known."""

    @property
    def verified(self) -> bool:
        return math.isfinite(self.payload_kg)


def segment_passes(tables: list[SignalsTable], kins: list[Any]) -> list[Pass]:
    """Passes from the phase machine on offline kinematics: a pass runs from one dig
    to the next; its estimation samples are lift and swing, as in the engine."""
    out: list[Pass] = []
    for ti, (table, kin) in enumerate(zip(tables, kins, strict=True)):
        ph = label_phases(kin)
        t = kin.t
        starts = np.flatnonzero((ph == DIG) & np.r_[True, ph[:-1] != DIG])
        for a, b in zip(starts, np.r_[starts[1:], len(t)], strict=True):
            seg = np.arange(a, b)
            dig = seg[ph[seg] == DIG]
            dig_end = t[dig[-1]] if len(dig) else t[a]
            est = seg[np.isin(ph[seg], (LIFT, SWING)) & (t[seg] >= dig_end + SETTLE_S)]
            if len(est) < 10:
                continue
            known = table.payload_truth()[est]
            known = known[np.isfinite(known)]
            payload = float(np.median(known)) if len(known) > 0.5 * len(est) else math.nan
            out.append(Pass(len(out) + 1, ti, float(t[a]), float(t[b - 1]), est, payload))
    return out


@dataclass
class View:
    """Calibration and measured data as one model sees them."""

    calib: list[FileData]
    measured: list[FileData]
    """``use`` here means "valid for this model", whether the payload is known or not."""
    truth: list[np.ndarray]
    """Scale payload per measured sample (NaN unknown)."""


def _key(model: Model) -> tuple[Any, ...]:
    parts: list[Any] = [any(getattr(t, "uses_field_current", False) for t in model.terms)]
    for t in model.terms:
        if type(t).transform is not Term.transform:  # the term re-shapes the signals
            parts.append((t.name, tuple(sorted(t.hyper.items()))))
    return tuple(parts)


VERIFIED_SUFFIX = " (verified passes)"
"""What a table's name gains in the training files when its verified passes are in them."""


@dataclass
class DataSet:
    """The calibration trials and the measured tables of one diagnosis."""

    calib: list[SignalsTable]
    measured: list[SignalsTable]
    exclusion: ExclusionConfig = field(default_factory=ExclusionConfig)
    window_s: float = DEFAULT_WINDOW_S
    polyorder: int = DEFAULT_POLYORDER
    _views: dict[tuple[Any, ...], View] = field(default_factory=dict)
    _calib_only: dict[tuple[Any, ...], list[FileData]] = field(default_factory=dict)
    passes: list[Pass] = field(default_factory=list)

    def __post_init__(self) -> None:
        base = self.view(Model.from_names([]))
        self.passes = segment_passes(self.measured, [f.kin for f in base.measured])

    def calib_files(self, model: Model) -> list[FileData]:
        """Only the calibration trials (what a hyper-parameter search on them needs)."""
        key = _key(model)
        if key in self._views:
            return self._views[key].calib
        if key not in self._calib_only:
            self._calib_only[key] = [exclusion_masks(t, model, self.exclusion, self.window_s,
                                                     self.polyorder)
                                     for t in self.calib]
        return self._calib_only[key]

    def view(self, model: Model) -> View:
        key = _key(model)
        if key not in self._views:
            calib = self.calib_files(model)
            measured, truth = [], []
            for t in self.measured:
                truth.append(t.payload_truth())
                # Validity without "payload unknown": fill the payload for the masks only.
                filled = SignalsTable(dict(t.columns), dict(t.meta), t.source)
                filled.columns["payload_kg"] = np.where(np.isfinite(truth[-1]), truth[-1], 0.0)
                measured.append(exclusion_masks(filled, model, self.exclusion,
                                                self.window_s, self.polyorder))
            self._views[key] = View(calib, measured, truth)
        return self._views[key]

    def training_files(self, model: Model, train: set[int] | None) -> list[FileData]:
        """Calibration files plus the verified passes in ``train`` (None: none)."""
        v = self.view(model) if train else None
        files = list(self.calib_files(model)) if v is None else list(v.calib)
        if not train or v is None:
            return files
        for ti, (f, truth) in enumerate(zip(v.measured, v.truth, strict=True)):
            sel = np.zeros(len(f.use), dtype=bool)
            for p in self.passes:
                if p.table == ti and p.index in train and p.verified:
                    sel[p.eval_idx] = True
            use = f.use & sel & np.isfinite(truth)
            if not use.any():
                continue
            files.append(replace(f, name=f"{f.name}{VERIFIED_SUFFIX}", payload=truth,
                                 use=use, static=f.static & use, excluded=Counter()))
        return files

    def calib_swing_s(self, rate: float) -> float:
        """How long the calibration trials swing faster than ``rate`` (rad/s), in seconds
        of the samples the fits use (are they swinging?). A time, not the largest rate:
        the swing angle's noise, differentiated, passes 0.1 rad/s now and then in trials
        that never swing (on 4 of 10 realistic machines), and the swing terms' values
        cannot be found from those."""
        base = self.calib_files(Model.from_names([]))
        total = 0.0
        for f in base:
            fast = f.use & (np.abs(np.nan_to_num(f.kin.swing_rate)) > rate)
            if len(f.kin.t) > 1:
                total += float(np.count_nonzero(fast)) * float(np.median(np.diff(f.kin.t)))
        return total
