"""The shovel model: an ordered set of named terms and the regressor they build."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

import numpy as np

from shoveld.model.kin import Kinematics
from shoveld.model.terms import BASE_TERMS, TERMS, Term, payload_phi

EQUATIONS: tuple[str, str] = ("handle", "crowd")
"""Residual channels: handle-rotation torque (N m) and crowd force (N)."""


class CurrentDerivatives(NamedTuple):
    """``Model.current_derivatives``: the parameters' columns that move with the measured
    hoist current (``hoist``, an index into the parameters) and d W / d i_H there
    (``d_hoist``, (N, 2, len)); the same for the crowd current."""

    hoist: slice | np.ndarray
    d_hoist: np.ndarray
    crowd: slice | np.ndarray
    d_crowd: np.ndarray


def _index(cols: list[int]) -> slice | np.ndarray:
    """Column indices as a slice when they are one run (a view into the parameters, not
    a copy: the live engine takes them every block)."""
    if cols and cols == list(range(cols[0], cols[-1] + 1)):
        return slice(cols[0], cols[-1] + 1)
    return np.asarray(cols, dtype=int)


def _columns(parts: list[np.ndarray], n: int) -> np.ndarray:
    """Terms' (N, 2, k) columns side by side (the one term's own array, uncopied)."""
    if len(parts) == 1:
        return parts[0]
    return np.concatenate(parts, axis=2) if parts else np.zeros((n, 2, 0))


class Model:
    """The base model plus any extension terms, in a fixed order."""

    def __init__(self, terms: Sequence[Term]) -> None:
        names = [t.name for t in terms]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate terms in {names}")
        self.terms: list[Term] = list(terms)
        self.param_names: list[str] = [p for t in self.terms for p in t.params]
        self.param_units: list[str] = [u for t in self.terms for u in t.units]
        self._spread_terms = [t for t in self.terms if t.spread_params]
        self._slices: list[slice] = []
        """Each term's parameters' columns."""
        start = 0
        for t in self.terms:
            self._slices.append(slice(start, start + len(t.params)))
            start += len(t.params)

    @classmethod
    def from_names(cls, effects: Iterable[str] = (),
                   hyper: dict[str, dict[str, Any]] | None = None) -> Model:
        """The base terms followed by the named extension terms."""
        hyper = hyper or {}
        names = list(BASE_TERMS) + [e for e in effects if e not in BASE_TERMS]
        unknown = [n for n in names if n not in TERMS]
        if unknown:
            raise ValueError(f"unknown model term(s) {unknown}; known: {sorted(TERMS)}")
        return cls([TERMS[n](**hyper.get(n, {})) for n in names])

    @property
    def term_names(self) -> list[str]:
        return [t.name for t in self.terms]

    @property
    def effects(self) -> list[str]:
        """The terms beyond the base model."""
        return [t.name for t in self.terms if not t.base]

    def transform(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        for t in self.terms:
            cols = t.transform(cols)
        return cols

    def regressor(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """W (N,2,P), phi (N,2) and Psi (N,2,P) with e = W p + m (phi + Psi p)."""
        n, n_p = len(k), len(self.param_names)
        # equation-major in memory, (N, 2, P) in shape: each equation's (N, P) block is
        # contiguous, as the output-error fits take them (shoveld.model.output)
        w_all = np.empty((2, n, n_p)).transpose(1, 0, 2)
        psi_all = np.zeros((2, n, n_p)).transpose(1, 0, 2)
        # each term's columns written into its slice (the live engine builds this for
        # every block of ten samples: one array, not one per term and a concatenation)
        for t, cols in zip(self.terms, self._slices, strict=True):
            w_all[:, :, cols] = t.columns(k)
            ps = t.payload_columns(k)
            if ps is not None:
                psi_all[:, :, cols] = ps
        phi = payload_phi(k)
        # An extension may change what existing parameters multiply (e.g. swing adds a
        # centrifugal part to the arm's mass columns) and add known per-kg payload physics.
        for t in self.terms:
            shared = getattr(t, "shared_columns", None)
            if shared is not None:
                for name, col in shared(k).items():
                    if name not in self.param_names:
                        raise ValueError(f"term {t.name!r} adds to parameter {name!r}, "
                                         "which no term of the model has")
                    w_all[:, :, self.param_names.index(name)] += col
            extra_phi = getattr(t, "payload_phi", None)
            if extra_phi is not None:
                phi = phi + extra_phi(k)
        return w_all, phi, psi_all

    def column_spread(self, k: Kinematics) -> tuple[np.ndarray, np.ndarray]:
        """The columns the kinematics do not determine (``Term.spread_params``): their
        parameter indices (K,) and standard deviations (N, 2, K)."""
        idx: list[int] = []
        parts = []
        for t in self._spread_terms:
            idx.extend(self.param_names.index(n) for n in t.spread_params)
            parts.append(t.column_spread(k))
        if not parts:
            return np.zeros(0, dtype=int), np.zeros((len(k), 2, 0))
        return np.asarray(idx, dtype=int), np.concatenate(parts, axis=2)

    def current_derivatives(self, k: Kinematics) -> CurrentDerivatives:
        """How the residual of each equation moves per ampere of measured hoist and crowd
        current, per unit of each parameter (terms linear in a measured current; see
        ``Term.current_derivative``): only the few columns that do move (the drives'),
        not (N, 2, P) arrays of zeros that every fit's Jacobian worked through."""
        h_cols: list[int] = []
        c_cols: list[int] = []
        dh: list[np.ndarray] = []
        dc: list[np.ndarray] = []
        for t, cols in zip(self.terms, self._slices, strict=True):
            d = t.current_derivative(k)
            if d is None:
                continue
            for got, idx, parts in zip(d, (h_cols, c_cols), (dh, dc), strict=True):
                if got is not None:
                    idx.extend(range(cols.start, cols.stop))
                    parts.append(got)
        return CurrentDerivatives(_index(h_cols), _columns(dh, len(k)),
                                  _index(c_cols), _columns(dc, len(k)))

    @property
    def offset_index(self) -> tuple[int, int] | None:
        """Indices of the hoist and crowd current offsets among the parameters."""
        if "i_H0" in self.param_names and "i_C0" in self.param_names:
            return self.param_names.index("i_H0"), self.param_names.index("i_C0")
        return None

    def payload_equations(self, k: Kinematics, p: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
        """(a, b), each (N, 2), such that the payload m satisfies a * m = b."""
        w, phi, psi = self.regressor(k)
        return phi + psi @ p, -(w @ p)

    def residual(self, k: Kinematics, p: np.ndarray, m: np.ndarray | float) -> np.ndarray:
        """(N, 2) equation residuals for parameters p and payload m."""
        w, phi, psi = self.regressor(k)
        m = np.broadcast_to(np.asarray(m, dtype=float), (len(k),))[:, None]
        return w @ p + m * (phi + psi @ p)
