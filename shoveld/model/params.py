"""Identified model parameters and their TOML file (``shoveld-params/1``).

The file records which terms the model has (so the same model is rebuilt by
``estimate`` and the daemon), every parameter with its standard error, the
covariance, and the residual noise per equation that the live payload filter
uses as its measurement noise.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shoveld.model.model import EQUATIONS, Model
from shoveld.model.terms import TERMS

PARAMS_FORMAT = "shoveld-params/1"


class ParamsFileError(ValueError):
    """A params file that cannot be used, with the file and key named."""


@dataclass
class ModelParams:
    """A model (its term names and hyper-parameters) with identified values."""

    terms: list[str]
    names: list[str]
    values: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray
    noise: dict[str, float]
    """Residual RMS per equation on the calibration data (N m, N)."""
    hyper: dict[str, dict[str, Any]] = field(default_factory=dict)
    fit: dict[str, Any] = field(default_factory=dict)
    current_noise: dict[str, dict[str, float]] = field(default_factory=dict)
    """Per current channel (hoist, crowd): the noise model by which the payload filter
    weights each sample, and the calibration residuals' correlation time, a record for
    the field engineer (a pass's std comes from its own residuals; keys
    ``shoveld.model.output.NOISE_KEYS``)."""

    def fingerprint(self) -> str:
        """A short digest of what weighs: the terms, their settings and the identified
        values and noise. The pass log keeps it, so that a restart carries on the checks
        of the same calibration and not of the one before it."""
        import hashlib
        import json

        doc = {"terms": self.terms, "hyper": self.hyper, "names": self.names,
               "values": [repr(float(v)) for v in self.values],
               "noise": {k: repr(float(v)) for k, v in sorted(self.noise.items())}}
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()
                              ).hexdigest()[:16]

    def model(self) -> Model:
        m = Model.from_names([t for t in self.terms], self.hyper)
        if m.param_names != self.names:
            raise ParamsFileError(
                f"parameters {self.names} do not match the terms' parameters {m.param_names}")
        return m

    def get(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def as_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.values, strict=True)}


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, np.generic):
        return _toml_value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _key(k: str) -> str:
    """A bare TOML key where allowed, else a quoted one."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _toml_value(k)


def _table(lines: list[str], header: str, d: dict[str, Any]) -> None:
    lines.append(f"\n[{header}]")
    for k, v in d.items():
        if isinstance(v, dict):
            continue
        lines.append(f"{_key(k)} = {_toml_value(v)}")
    for k, v in d.items():
        if isinstance(v, dict):
            _table(lines, f"{header}.{_key(k)}", v)


def save_params(path: str | Path, p: ModelParams, units: list[str] | None = None) -> None:
    units = units or p.model().param_units
    lines = [f'format = "{PARAMS_FORMAT}"',
             f"terms = {_toml_value(p.terms)}"]
    for n, v, se, u in zip(p.names, p.values, p.stderr, units, strict=True):
        _table(lines, f"params.{n}", {"value": float(v), "stderr": float(se), "unit": u})
    _table(lines, "noise", {k: float(v) for k, v in p.noise.items()})
    if p.current_noise:
        _table(lines, "current_noise", {k: {n: float(x) for n, x in v.items()}
                                        for k, v in p.current_noise.items()})
    for term, h in p.hyper.items():
        if h:
            _table(lines, f"hyper.{term}", h)
    if p.fit:
        _table(lines, "fit", p.fit)
    _table(lines, "covariance", {"names": p.names,
                                 "matrix": [[float(x) for x in row] for row in p.cov]})
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def load_params(path: str | Path) -> ModelParams:
    """Read a params file; every fault names the file and the key."""
    spath = str(path)
    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as e:
        raise ParamsFileError(f"{spath}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise ParamsFileError(f"{spath}: not a text file (byte {e.start} is not UTF-8); "
                              "expected a params file written by 'shoveld calibrate'") from None
    except tomllib.TOMLDecodeError as e:
        raise ParamsFileError(f"{spath}: not valid TOML: {e}") from None

    def need(d: dict[str, Any], key: str, where: str, typ: type | tuple[type, ...]) -> Any:
        if key not in d:
            raise ParamsFileError(f"{spath}: missing key '{where}{key}'")
        if not isinstance(d[key], typ):
            raise ParamsFileError(f"{spath}: key '{where}{key}' has the wrong type "
                                  f"({type(d[key]).__name__})")
        return d[key]

    fmt = need(doc, "format", "", str)
    if fmt != PARAMS_FORMAT:
        raise ParamsFileError(f"{spath}: key 'format' is {fmt!r}, expected {PARAMS_FORMAT!r}")
    terms = need(doc, "terms", "", list)
    hyper = doc.get("hyper", {})
    if not isinstance(hyper, dict) or not all(isinstance(v, dict) for v in hyper.values()):
        raise ParamsFileError(f"{spath}: key 'hyper' must be a table of tables (one per term)")
    try:
        # each term's keys as they were before a file carried them (its form then)
        hyper = {n: (TERMS[n].file_hyper(h) if n in TERMS else h) for n, h in hyper.items()}
        model = Model.from_names(terms, hyper)
    except ValueError as e:
        where = "" if str(e).startswith("hyper.") else "key 'terms': "
        raise ParamsFileError(f"{spath}: {where}{e}") from None
    params = need(doc, "params", "", dict)
    values, stderr = [], []
    for n in model.param_names:
        entry = need(params, n, "params.", dict)
        v = float(need(entry, "value", f"params.{n}.", (int, float)))
        if not math.isfinite(v):
            raise ParamsFileError(f"{spath}: key 'params.{n}.value' is {v}; expected a finite "
                                  "number")
        values.append(v)
        se = entry.get("stderr", math.nan)
        if not isinstance(se, int | float) or (math.isfinite(se) and se < 0) or se == math.inf:
            raise ParamsFileError(f"{spath}: key 'params.{n}.stderr' must be a non-negative "
                                  f"number (or nan when unknown), got {se!r}")
        stderr.append(float(se))
    extra = set(params) - set(model.param_names)
    if extra:
        raise ParamsFileError(f"{spath}: keys {sorted('params.' + e for e in extra)} belong to "
                              f"no term in 'terms' {terms}")
    noise_d = need(doc, "noise", "", dict)
    noise = {eq: float(need(noise_d, eq, "noise.", (int, float))) for eq in EQUATIONS}
    for eq, v in noise.items():
        if not (math.isfinite(v) and v > 0):
            raise ParamsFileError(f"{spath}: key 'noise.{eq}' must be a positive number")
    # The covariance carries the calibration's uncertainty into every pass's std: a file
    # without it (hand-written, or cut) falls back to the standard errors alone, and one
    # that is there must fit the parameters.
    cov_d = doc.get("covariance", {})
    if not isinstance(cov_d, dict):
        raise ParamsFileError(f"{spath}: key 'covariance' must be a table")
    n_params = len(values)
    cov = np.diag(np.square(np.nan_to_num(stderr)))
    if cov_d:
        if cov_d.get("names") != model.param_names:
            raise ParamsFileError(f"{spath}: key 'covariance.names' must list the parameters "
                                  f"{model.param_names} in that order")
        try:
            c = np.asarray(cov_d.get("matrix"), dtype=float)
        except (TypeError, ValueError):
            c = np.zeros(0)
        if c.shape != (n_params, n_params) or not np.all(np.isfinite(c)):
            raise ParamsFileError(f"{spath}: key 'covariance.matrix' must be a {n_params} x "
                                  f"{n_params} table of finite numbers")
        cov = c
    from shoveld.model.output import CHANNELS, NOISE_KEYS

    current_noise: dict[str, dict[str, float]] = {}
    cn = doc.get("current_noise", {})
    if not isinstance(cn, dict):
        raise ParamsFileError(f"{spath}: key 'current_noise' must be a table")
    for ch in CHANNELS if cn else ():
        v = need(cn, ch, "current_noise.", dict)
        current_noise[ch] = {}
        for key in NOISE_KEYS:
            x = need(v, key, f"current_noise.{ch}.", (int, float))
            if not (math.isfinite(x) and x >= 0):
                raise ParamsFileError(f"{spath}: key 'current_noise.{ch}.{key}' must be a "
                                      "non-negative number")
            current_noise[ch][key] = float(x)
    # The fit's record is for people, except the verified passes' ratio to the trials,
    # which check-config and the daemon's health read (shoveld.payload.misfit)
    fit = doc.get("fit", {})
    if not isinstance(fit, dict):
        raise ParamsFileError(f"{spath}: key 'fit' must be a table")
    ratio = fit.get("passes_to_trials_rms", {})
    if not isinstance(ratio, dict) or not all(
            isinstance(r, int | float) and not isinstance(r, bool) and math.isfinite(r)
            and r > 0 for r in ratio.values()):
        raise ParamsFileError(f"{spath}: key 'fit.passes_to_trials_rms' must be a table of "
                              f"positive numbers, one per channel; got {ratio!r}")
    return ModelParams(terms=list(model.term_names), names=model.param_names,
                       values=np.asarray(values), stderr=np.asarray(stderr), cov=cov,
                       noise=noise, hyper={k: dict(v) for k, v in hyper.items()},
                       fit=dict(fit), current_noise=current_noise)
