"""The result of :meth:`sysid.Problem.fit`."""

from __future__ import annotations

import json
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np


class FitResult:
    """A fit, as ``sysid fit --format json`` prints it (docs/json.md: every key is in
    :attr:`record`); the common ones as attributes, arrays in the problem's order."""

    def __init__(self, record: Union[str, Dict[str, Any]]) -> None:
        #: The fit's JSON object (docs/json.md), as a dict.
        self.record: Dict[str, Any] = json.loads(record) if isinstance(record, str) else record
        r = self.record
        #: The unknowns' names, in the order of :attr:`x`.
        self.parameter_names: List[str] = list(r["estimates"])
        #: The estimates by name, on the linear scale.
        self.estimates: Dict[str, float] = dict(r["estimates"])
        #: The estimates as an array, on the linear scale.
        self.x: np.ndarray = np.array([r["estimates"][n] for n in self.parameter_names])
        #: √(diag Cov) by name (None where the covariance is not defined).
        self.std_errors: Dict[str, Optional[float]] = dict(r["std_errors"])
        #: 95 % confidence intervals by name: (low, high), or None.
        self.intervals: Dict[str, Optional[Tuple[float, float]]] = {
            n: (tuple(v) if v is not None else None) for n, v in r["intervals"].items()
        }
        #: Whether the returned point passes the first-order certificate (docs/terminations.md).
        self.converged: bool = r["converged"]
        #: Why the method stopped, in words.
        self.termination: str = r["termination"]
        #: The stable tag of :attr:`termination`.
        self.termination_code: str = r["termination_code"]
        #: The negative log-likelihood at the estimates (priors excluded).
        self.nll: Optional[float] = r["nll"]
        #: Its integration error.
        self.nll_error: Optional[float] = r.get("nll_error")
        #: The negative log-prior, where the problem has priors, else 0.
        self.prior: float = r.get("prior") or 0.0
        #: What the fit minimised: :attr:`nll` plus :attr:`prior`.
        self.objective: Optional[float] = None if self.nll is None else self.nll + self.prior
        #: The unknowns the model does not respond to at the estimates.
        self.undetermined: List[str] = list(r["undetermined"])
        #: The unknowns held on a bound: name → "lower" or "upper", or "prior_location" (held on
        #: the location of its Laplace prior, where the rest of the gradient is within its slope).
        self.active_bounds: Dict[str, str] = dict(r["active_bounds"])
        #: The method's iterations.
        self.iterations: int = r["iterations"]
        #: Wall-clock time of the fit (of every start, with starts), in seconds.
        self.elapsed: float = (r["starts"]["elapsed_ms"] if "starts" in r else r["elapsed_ms"]) / 1e3
        #: What the starts found (the ``starts`` object of docs/json.md), or None.
        self.starts: Optional[Dict[str, Any]] = r.get("starts")

    @property
    def waterfall(self) -> Dict[str, np.ndarray]:
        """Every start's outcome, least objective first, as arrays: ``start``,
        ``objective`` (nan where the fit could not begin), ``converged``,
        ``termination_code``, ``iterations`` and ``elapsed`` (seconds); ``x0`` and ``x``,
        where each start began and ended (a row per start, columns in
        :attr:`parameter_names`' order). Empty arrays without starts."""
        rows = self.starts["waterfall"] if self.starts else []
        names = self.parameter_names

        def points(key: str) -> np.ndarray:
            table = [[w[key].get(n, np.nan) for n in names] for w in rows]
            return np.array(table, dtype=float).reshape(len(rows), len(names))

        return {
            "start": np.array([w["start"] for w in rows], dtype=int),
            "objective": np.array(
                [np.nan if w["objective"] is None else w["objective"] for w in rows], dtype=float
            ),
            "converged": np.array([w["converged"] for w in rows], dtype=bool),
            "termination_code": np.array([w["termination_code"] for w in rows], dtype=object),
            "iterations": np.array([w["iterations"] for w in rows], dtype=int),
            "elapsed": np.array([w["elapsed_ms"] / 1e3 for w in rows], dtype=float),
            "x0": points("start_values"),
            "x": points("estimates"),
        }

    def __repr__(self) -> str:
        state = "converged" if self.converged else f"not converged ({self.termination_code})"
        return f"FitResult(nll={self.nll!r}, {state}, {self.iterations} iterations)"


class Profile:
    """One unknown's profile likelihood (docs/json.md, "A profile")."""

    def __init__(self, name: str, record: Dict[str, Any]) -> None:
        #: The unknown.
        self.name = name
        low, high = record["interval"]
        #: The 95 % interval (low, high); None at an end whose side did not cross the threshold.
        self.interval: Tuple[Optional[float], Optional[float]] = (low, high)
        #: ``identifiable``, ``practically_non_identifiable``, ``undecided`` (the point budget
        #: ran out before the profile crossed the threshold while it was still rising),
        #: ``structurally_non_identifiable`` or ``failed`` (a fit along the profile panicked, a
        #: defect in sysid: no verdict).
        self.label: str = record["label"]
        #: None, or the message of the panic that ended a side's tracing (the points before it
        #: are kept).
        self.failed: Optional[str] = record.get("failed")
        points = record["points"]
        #: The profiled unknown's values, increasing, the optimum's included.
        self.values = np.array([p["value"] for p in points], dtype=float)
        #: The NLL minimised over the others at each value (nan where it could not be evaluated).
        self.nll = np.array([np.nan if p["nll"] is None else p["nll"] for p in points], dtype=float)
        #: Whether each point's fit converged.
        self.converged = np.array([p["converged"] for p in points], dtype=bool)
        #: Every unknown's value at each point (a row per point).
        self.estimates = np.array([p["estimates"] for p in points], dtype=float)

    def __repr__(self) -> str:
        return f"Profile({self.name!r}, interval={self.interval}, {self.label})"


class ProfileResult:
    """Profile likelihoods, as ``sysid profile --format json`` prints them (docs/json.md)."""

    def __init__(self, record: str) -> None:
        #: The JSON object, as a dict.
        self.record: Dict[str, Any] = json.loads(record)
        #: The fit the profiles are around.
        self.optimum = FitResult(self.record["optimum"])
        #: That fit converged and no profile found a lower point.
        self.from_certified_optimum: bool = self.record["from_certified_optimum"]
        #: ΔNLL at which a profile side ends.
        self.threshold: float = self.record["threshold"]
        #: The profiles by unknown.
        self.profiles: Dict[str, Profile] = {n: Profile(n, p) for n, p in self.record["profiles"].items()}

    def __repr__(self) -> str:
        return f"ProfileResult({len(self.profiles)} profiles, threshold {self.threshold})"
