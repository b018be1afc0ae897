"""Drift: which robot's parameters changed over time, at which recording, and which robots differ from the fleet.

The tests use each identification's own standard deviations (``<name>_std`` of the fleet table), not a
threshold on the values.

**Parameters tested** (:func:`drift_parameters`): the ones wear and tools change and whose meaning does
not depend on the base-parameter grouping: Coulomb and viscous friction (``fc<j>``, ``fv<j>``) and the
armature (``ia<j>``) of every joint, and the base parameters a :data:`dynid.fleet.core.TOOL_MASS` kg
tool at the tool frame moves by more than :data:`TOOL_SIGMAS` of their median standard deviation (the
last link's first moments and the grouped inertias and masses of the links before it, whatever their
grouped names: the shift is computed through the base-parameter map, not guessed from names).

**Change over time**, per robot and parameter, with the robot's recordings in time order, values
``x_k`` and variances ``s_k^2`` (times the fleet's :ref:`inflation <inflation>` of that parameter):

* constancy: ``chi2 = sum_k (x_k - xbar)^2 / s_k^2`` with the weighted mean ``xbar``, ``K - 1`` degrees
  of freedom (reported);
* a change point: for each split after recording ``c`` the likelihood ratio of two constant levels
  against one, ``LR_c = chi2 - chi2_before(c) - chi2_after(c)`` (chi-square with 1 degree of freedom
  at a fixed split); the scan takes the largest, its p-value is Bonferroni-corrected over the ``K - 1``
  splits, and the recording of change is the first after the best split.

Over all robots x parameters the change p-values are adjusted by Holm's method
(:func:`dynid.diagnosis.stats.holm`; family-wise error rate ``alpha``, default 0.05); a test below ``alpha`` flags its robot.

.. _inflation:

**Inflation.**  An identification's standard deviation assumes its residuals are what its weighting
says; filtered, coloured sensor noise makes the spread between repeated recordings somewhat larger.
Per parameter the fleet itself measures it: the median over robots of ``chi2 / median(chi2_{K-1})``,
at least 1, multiplies every variance of that parameter.  A median is not moved by the few robots that
changed; the factor is reported.

**Robots that differ from the fleet**, per parameter: each robot's weighted mean (over its recordings
since its last flagged change, or all of them) against the fleet's median, in units of the fleet's
robust spread (1.4826 MAD of the robots' means: manufacturing tolerance) and the robot's own standard
error combined; two-sided normal p-values, Holm over robots x parameters.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dynid.diagnosis.stats import holm
from dynid.exceptions import UsageError

# ``holm`` is the diagnosis' (:func:`dynid.diagnosis.stats.holm`), named here as well for the fleet's callers.
__all__ = ["TOOL_SIGMAS", "DriftResult", "DriftTest", "FleetOutlier", "detect_drift", "drift_parameters", "holm"]

TOOL_SIGMAS = 3.0
"""A base parameter is tested when the tool moves it by more than this many of its median standard deviations."""

MIN_FLEET = 5
"""Robots needed for the test against the fleet (the fleet's spread is a median of absolute deviations)."""

_KINDS = ("coulomb", "viscous", "armature")


@dataclass(frozen=True)
class DriftTest:
    """One robot's test of one parameter for change over time.

    Attributes
    ----------
    robot, parameter : str
    kind : str
        ``link``, ``armature``, ``coulomb`` or ``viscous``.
    recordings : int
        Recordings in the test (K).
    chi2, p_constant : float
        Constancy statistic (K - 1 degrees of freedom) and its p-value.
    lr, p_change : float
        Largest change-point likelihood ratio and its p-value (Bonferroni over the splits).
    p_adjusted : float
        ``p_change`` adjusted by Holm over every robot x parameter.
    change_order : int
        Order (from 0) of the first recording after the best split.
    change_time, change_path : str
        Its time and file.
    before, after : float
        Weighted means before and after the split (SI units).
    shift_sigma : float
        ``(after - before)`` over its standard error.
    flagged : bool
        ``p_adjusted < alpha``.
    """

    robot: str
    parameter: str
    kind: str
    recordings: int
    chi2: float
    p_constant: float
    lr: float
    p_change: float
    p_adjusted: float
    change_order: int
    change_time: str
    change_path: str
    before: float
    after: float
    shift_sigma: float
    flagged: bool


@dataclass(frozen=True)
class FleetOutlier:
    """One robot's parameter against the fleet.

    Attributes
    ----------
    robot, parameter : str
    mean, se : float
        The robot's weighted mean and its standard error (SI units).
    fleet_median, fleet_spread : float
        The fleet's median of the robots' means and its robust spread.
    z, p, p_adjusted : float
        Standardised distance, two-sided p-value, Holm-adjusted.
    flagged : bool
    """

    robot: str
    parameter: str
    mean: float
    se: float
    fleet_median: float
    fleet_spread: float
    z: float
    p: float
    p_adjusted: float
    flagged: bool


@dataclass(frozen=True, eq=False)
class DriftResult:
    """The drift tests of a fleet.

    Attributes
    ----------
    tests : list of DriftTest
        Every robot x parameter tested (robots with at least two identified recordings).
    outliers : list of FleetOutlier
        Every robot x parameter against the fleet (fleets of at least :data:`MIN_FLEET` robots).
    parameters : list of str
        The parameters tested.
    inflation : dict of str to float
        The variance factor of each parameter (see the module's docstring).
    alpha : float
    """

    tests: list[DriftTest]
    outliers: list[FleetOutlier]
    parameters: list[str]
    inflation: dict[str, float]
    alpha: float
    series: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def flagged(self) -> list[DriftTest]:
        """The flagged tests, most significant first."""
        return sorted((t for t in self.tests if t.flagged), key=lambda t: (t.p_adjusted, -abs(t.shift_sigma)))

    @property
    def flagged_robots(self) -> dict[str, list[DriftTest]]:
        """Robot -> its flagged tests (most significant first), robots in order of their strongest test."""
        out: dict[str, list[DriftTest]] = {}
        for test in self.flagged:
            out.setdefault(test.robot, []).append(test)
        return out

    @property
    def fleet_outliers(self) -> dict[str, list[FleetOutlier]]:
        """Robot -> its parameters that differ from the fleet."""
        out: dict[str, list[FleetOutlier]] = {}
        for o in sorted((o for o in self.outliers if o.flagged), key=lambda o: o.p_adjusted):
            out.setdefault(o.robot, []).append(o)
        return out

    def summary(self) -> str:
        """One line per flagged robot: its parameters and the recording of change."""
        flagged = self.flagged_robots
        lines = [
            f"drift: {len(self.parameters)} parameters x {len({t.robot for t in self.tests})} robots tested "
            f"(Holm, alpha {self.alpha:g}); {len(flagged)} robot{'s' if len(flagged) != 1 else ''} flagged"
        ]
        for robot, tests in flagged.items():
            parts = ", ".join(
                f"{t.parameter} {t.before:.4g} -> {t.after:.4g} ({t.shift_sigma:+.1f} sd) from recording "
                f"{t.change_order} ({t.change_time})"
                for t in tests[:4]
            )
            more = f" and {len(tests) - 4} more" if len(tests) > 4 else ""
            lines.append(f"  {robot}: {parts}{more}")
        outliers = self.fleet_outliers
        if outliers:
            lines.append(
                "differ from the fleet: "
                + "; ".join(f"{r} ({', '.join(o.parameter for o in os_[:3])})" for r, os_ in outliers.items())
            )
        return "\n".join(lines)

    def to_csv(self) -> str:
        """Every test as CSV (one row per robot x parameter)."""
        buffer = io.StringIO()
        names = list(DriftTest.__dataclass_fields__)
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(names)
        for t in self.tests:
            writer.writerow([repr(v) if isinstance(v, float) else v for v in (getattr(t, k) for k in names)])
        return buffer.getvalue()

    def figures(self) -> dict[str, Any]:
        """JSON-ready figures: the flagged robots and tests, the outliers, the inflation factors."""
        return {
            "alpha": self.alpha,
            "parameters": self.parameters,
            "inflation": self.inflation,
            "flagged": {
                robot: [
                    {k: getattr(t, k) for k in ("parameter", "change_order", "change_time", "before", "after",
                                                 "shift_sigma", "p_adjusted")}
                    for t in tests
                ]
                for robot, tests in self.flagged_robots.items()
            },
            "fleet_outliers": {
                robot: [{"parameter": o.parameter, "z": o.z, "p_adjusted": o.p_adjusted} for o in os_]
                for robot, os_ in self.fleet_outliers.items()
            },
        }


def drift_parameters(parameters: list[dict[str, Any]], median_std: dict[str, float]) -> list[str]:
    """The parameters the drift tests look at (see the module's docstring).

    Parameters
    ----------
    parameters : list of dict
        :func:`dynid.fleet.core.parameter_table`.
    median_std : dict of str to float
        Median standard deviation of each parameter over the fleet's recordings.

    Returns
    -------
    list of str
    """
    chosen = []
    for p in parameters:
        name = p["name"]
        if p["kind"] in _KINDS:
            chosen.append(name)
        elif p["kind"] == "link":
            sd = median_std.get(name, np.inf)
            if abs(p["tool_shift"]) > TOOL_SIGMAS * sd:
                chosen.append(name)
    return chosen


def _levels(x: np.ndarray, w: np.ndarray) -> float:
    """Weighted sum of squares about the weighted mean."""
    mean = np.sum(w * x) / np.sum(w)
    return float(np.sum(w * (x - mean) ** 2))


def _scan(x: np.ndarray, v: np.ndarray) -> tuple[float, float, int, float, float, float]:
    """chi2, best LR, best split c (first index after), before, after, shift in sd."""
    w = 1.0 / v
    chi2 = _levels(x, w)
    best, split = -1.0, 1
    for c in range(1, x.size):
        lr = chi2 - _levels(x[:c], w[:c]) - _levels(x[c:], w[c:])
        if lr > best + 1e-12 * max(chi2, 1.0):
            best, split = lr, c
    wb, wa = w[:split], w[split:]
    before, after = np.sum(wb * x[:split]) / np.sum(wb), np.sum(wa * x[split:]) / np.sum(wa)
    se = np.sqrt(1.0 / np.sum(wb) + 1.0 / np.sum(wa))
    return chi2, max(best, 0.0), split, float(before), float(after), float((after - before) / se)


def detect_drift(result: Any, *, alpha: float = 0.05, parameters: list[str] | None = None) -> DriftResult:
    """Test every robot's parameters for change over time, and every robot against the fleet.

    Parameters
    ----------
    result : FleetResult
        The fleet's table (:func:`dynid.fleet.core.identify_fleet` with ``drift=False``, or its result).
    alpha : float
        Family-wise error rate over robots x parameters (Holm), in (0, 1).
    parameters : list of str, optional
        Parameters to test; default :func:`drift_parameters`.

    Returns
    -------
    DriftResult
    """
    from scipy import stats

    if not 0.0 < alpha < 1.0:
        raise UsageError(f"alpha is {alpha}; give a family-wise error rate between 0 and 1, e.g. 0.05.")
    rows = [r for r in result.rows if not r.get("error")]
    known = {p["name"] for p in result.parameters}
    median_std = {
        name: float(np.median([r[f"{name}_std"] for r in rows if f"{name}_std" in r])) for name in known
    }
    if parameters is None:
        parameters = drift_parameters(result.parameters, median_std)
    unknown = [p for p in parameters if p not in known]
    if unknown:
        raise UsageError(
            f"the drift parameters {', '.join(unknown)} are not in the fleet's table; choose among "
            f"{', '.join(p['name'] for p in result.parameters)}."
        )
    kinds = {p["name"]: p["kind"] for p in result.parameters}
    by_robot: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_robot.setdefault(row["robot"], []).append(row)
    for robot_rows in by_robot.values():
        robot_rows.sort(key=lambda r: r["order"])
    series: dict[str, Any] = {}
    raw: list[tuple[str, str, np.ndarray, np.ndarray, list[dict[str, Any]]]] = []
    for robot, robot_rows in by_robot.items():
        for name in parameters:
            x = np.array([r[name] for r in robot_rows], dtype=float)
            s = np.array([r[f"{name}_std"] for r in robot_rows], dtype=float)
            # a parameter held at its bound has no spread of its own: the fleet's median stands in
            s = np.where(np.isfinite(s) & (s > 0), s, median_std[name] if median_std[name] > 0 else 1.0)
            raw.append((robot, name, x, s**2, robot_rows))
    inflation: dict[str, float] = {}
    for name in parameters:
        ratios = [
            _levels(x, 1.0 / v) / stats.chi2.median(x.size - 1) for _, nm, x, v, _ in raw if nm == name and x.size > 1
        ]
        inflation[name] = float(max(1.0, np.median(ratios))) if ratios else 1.0
    tests: list[DriftTest] = []
    pending: list[tuple[Any, ...]] = []
    for robot, name, x, v, robot_rows in raw:
        v = v * inflation[name]
        series[f"{robot}\t{name}"] = {
            "time": [r["time"] for r in robot_rows],
            "order": [r["order"] for r in robot_rows],
            "value": x.tolist(),
            "std": np.sqrt(v).tolist(),
        }
        if x.size < 2:
            continue
        chi2, lr, split, before, after, shift = _scan(x, v)
        p_const = float(stats.chi2.sf(chi2, x.size - 1))
        p_change = float(min(1.0, (x.size - 1) * stats.chi2.sf(lr, 1)))
        pending.append((robot, name, x.size, chi2, p_const, lr, p_change, split, before, after, shift, robot_rows))
    adjusted = holm(np.array([p[6] for p in pending]))
    for item, p_adj in zip(pending, adjusted, strict=True):
        robot, name, k, chi2, p_const, lr, p_change, split, before, after, shift, robot_rows = item
        tests.append(
            DriftTest(
                robot, name, kinds[name], int(k), float(chi2), p_const, float(lr), p_change, float(p_adj),
                int(robot_rows[split]["order"]), str(robot_rows[split]["time"]), str(robot_rows[split]["path"]),
                before, after, shift, bool(p_adj < alpha),
            )
        )
    outliers = _fleet_outliers(raw, inflation, tests, alpha)
    return DriftResult(tests, outliers, list(parameters), inflation, float(alpha), series)


def _fleet_outliers(raw, inflation, tests, alpha) -> list[FleetOutlier]:
    from scipy import stats

    change = {}
    for t in tests:
        if t.flagged:
            change[t.robot] = max(change.get(t.robot, 0), t.change_order)
    per_param: dict[str, list[tuple[str, float, float]]] = {}
    for robot, name, x, v, robot_rows in raw:
        keep = np.array([r["order"] >= change.get(robot, 0) for r in robot_rows])
        w = 1.0 / (v[keep] * inflation[name])
        per_param.setdefault(name, []).append((robot, float(np.sum(w * x[keep]) / np.sum(w)), float(np.sqrt(1 / np.sum(w)))))
    found = []
    for name, entries in per_param.items():
        if len(entries) < MIN_FLEET:
            continue
        means = np.array([e[1] for e in entries])
        median = float(np.median(means))
        spread = float(1.4826 * np.median(np.abs(means - median)))
        for robot, mean, se in entries:
            z = (mean - median) / np.sqrt(spread**2 + se**2)
            found.append([robot, name, mean, se, median, spread, float(z), float(2 * stats.norm.sf(abs(z)))])
    adjusted = holm(np.array([f[7] for f in found]))
    return [FleetOutlier(*f, float(a), bool(a < alpha)) for f, a in zip(found, adjusted, strict=True)]
