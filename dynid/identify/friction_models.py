"""The built-in single-joint friction models, the ``--friction`` choices besides ``auto``.

===============  ================================================================================================
``none``         no friction
``linear``       ``fc sign(dq) + fv dq + fo`` (Coulomb, viscous, offset; fc, fv >= 0)
``seed``         the paper's model (METHOD.md section 2), see :class:`SeedFriction`
``seed_shared``  the paper's model with one static level for both directions, see :class:`SharedSeedFriction`
``stribeck``     ``sign(dq) (fc + (fs - fc) exp(-(dq / vs)^2)) + fv dq + fo``
``sigmoid``      ``phi1 / (1 + exp(-phi2 (dq + phi3))) - phi1 / (1 + exp(-phi2 phi3))`` (Gaz et al. 2019,
                 Franka Emika Panda)
===============  ================================================================================================

A new model is a class here and a row of this table, its line in ``FRICTION_MODELS``
(:mod:`dynid.identify.registry`) and its test (docs/architecture.md, "A new friction model").
:class:`ShapedFriction` is the base of the models linear in their coefficients at a searched shape
parameter (the seed model's threshold is found by non-negative least squares); each model says what a
simulator's damping and frictionloss leave out of it."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._rest import AT_REST, direction
from dynid.exceptions import DataError
from dynid.identify.friction_base import FrictionModel
from dynid.identify.friction_fitting import (
    bounded_lsq,
    bounded_solve,
    compress_rows,
    near_candidates,
    sample_stride,
    shape_search,
)

__all__ = [
    "LinearFriction",
    "NoFriction",
    "SeedFriction",
    "ShapedFriction",
    "SharedSeedFriction",
    "SigmoidFriction",
    "StribeckFriction",
]

# What a simulator's damping and frictionloss leave out of the built-in models (FrictionModel.simulator_items)
_SIMULATOR_ITEMS = {
    "friction offset": "the constant torque fo of each joint (no simulator field)",
    "Stribeck friction": "the static level above the Coulomb level at low speed",
    "direction-dependent Coulomb friction": "different levels for positive and negative speed; their mean is "
    "the frictionloss",
    "nonlinear viscous friction": "the dq|dq| and dq^3 terms; only the linear term is damping",
    "sigmoid friction shape": "the smooth sigmoid and its shift; half its span is the frictionloss, no damping",
}


def _items(*whats: str) -> dict[str, str]:
    return {w: _SIMULATOR_ITEMS[w] for w in whats}


def _present(*flags: tuple[str, bool]) -> tuple[str, ...]:
    return tuple(what for what, on in flags if on)


class NoFriction(FrictionModel):
    """No friction: predicts zero."""

    name = "none"
    coef_names = ()

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        self._set([], float(F @ F), len(F))

    def columns(self, dq):
        return np.zeros((len(dq), 0))

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return {}

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        self._check_fitted()
        return 0.0, 0.0, ()


class LinearFriction(FrictionModel):
    """``F = fc sign(dq) + fv dq + fo`` with ``fc, fv >= 0`` (METHOD.md's linear baseline plus an offset).

    Fitted by bounded linear least squares.

    Parameters
    ----------
    offset : bool
        Fit the offset ``fo`` (N m); False fixes it at 0 (the paper's baseline).
    """

    name = "linear"
    coef_names = ("fc", "fv", "fo")
    bounds = (0.0, 0.0, -np.inf)
    _min_samples = 3

    def __init__(self, *, offset: bool = True) -> None:
        self.offset = offset

    @property
    def _linear(self) -> tuple[int, ...]:  # type: ignore[override]
        return (0, 1, 2) if getattr(self, "offset", True) else (0, 1)

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        k = 3 if self.offset else 2
        coef, rss = self._fit_columns(lambda v: self._columns(v)[:, :k], dq, F, sampling, self.bounds[:k])
        self._set(np.append(coef, 0.0) if k == 2 else coef, rss, len(F))

    @staticmethod
    def _columns(dq):
        return np.column_stack([direction(dq), dq, np.ones_like(dq)])

    def columns(self, dq):
        return self._columns(dq)[:, : len(self._linear)]

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("friction offset")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        return max(c["fv"], 0.0), max(c["fc"], 0.0), _present(("friction offset", abs(c["fo"]) > 0))


def _seed_columns(dq: NDArray[np.float64], lam: float) -> NDArray[np.float64]:
    """Columns of the seed model at threshold ``lam`` for ``[kc+, kc-, kv1, kv2, kv3, ks+, ks-]``.

    Written with whole-array ``np.where`` (the same values as per-region assignments, several times
    faster: the shape search evaluates it about a thousand times in a default identification).
    """
    return np.ascontiguousarray(_seed_rows(_SeedSpeeds(dq), lam).T)


class _SeedSpeeds:
    """What the seed model's columns need of ``dq`` at any threshold, computed once per search."""

    def __init__(self, dq: NDArray[np.float64]) -> None:
        self.dq = dq
        self.a = np.abs(dq)
        self.pos, self.neg = dq >= AT_REST, dq <= -AT_REST  # a joint at rest has no direction
        self.dqa = dq * self.a
        self.dq3 = dq**3


def _seed_rows(s: _SeedSpeeds, lam: float) -> NDArray[np.float64]:
    """:func:`_seed_columns` transposed, (7, len(dq)): the same values, written row by row."""
    high = s.a >= lam  # lam > 0: a high-speed sample moves
    r = s.a / lam
    low = ~high
    pl, nl = s.pos & low, s.neg & low
    # low speed: a straight line from the static level (at 0+) to the high-speed curve (at +-lam)
    signed = np.zeros(len(r))
    np.copyto(signed, r, where=pl)
    neg_r = -r
    np.copyto(signed, neg_r, where=nl)
    A = np.zeros((7, len(r)))
    np.copyto(A[0], r, where=pl)
    A[0][s.pos & high] = 1.0
    np.copyto(A[1], neg_r, where=nl)
    A[1][s.neg & high] = -1.0
    for k, (fast, power) in enumerate(((s.dq, lam), (s.dqa, lam**2), (s.dq3, lam**3)), start=2):
        np.multiply(signed, power, out=A[k])
        np.copyto(A[k], fast, where=high)
    one_minus = 1.0 - r
    np.copyto(A[5], one_minus, where=pl)
    np.negative(one_minus, out=one_minus)
    np.copyto(A[6], one_minus, where=nl)
    return A


class ShapedFriction(FrictionModel):
    """Models linear in their coefficients at a fixed shape parameter, the last coefficient.

    The shape parameter is searched among candidates between the quantiles ``quantiles`` of ``|dq|``
    (or near a previous value), each scored by the bounded linear least squares of the other
    coefficients; the coefficients are then fitted on all samples at the winner.  On filtered data the
    search filters a window of the record per candidate (see :class:`Sampling`).

    Attributes
    ----------
    candidates_ : ndarray
        The candidate shape parameters of the search.
    candidate_sse_ : ndarray
        The squared error of the fit at each candidate.
    """

    n_candidates: int
    quantiles: tuple[float, float]
    _min_samples = 20
    _search_label: ClassVar[str] = ""  # the model's name in messages
    _move_advice: ClassVar[str] = ""  # appended to the message when the joint hardly moves
    _refine: ClassVar[bool] = True  # refine the best candidate by golden section

    @staticmethod
    def _columns(dq: NDArray[np.float64], shape: float) -> NDArray[np.float64]:
        """Columns of the linear coefficients at shape parameter ``shape``: (len(dq), k)."""
        raise NotImplementedError

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        a = np.abs(dq_k[np.abs(dq_k) >= AT_REST])  # a joint at rest has no direction (dynid._rest)
        if a.size < 20:
            raise DataError(
                f"the {self._search_label} friction model needs the joint to move; only {a.size} samples "
                f"have |dq| >= {AT_REST:g} rad/s (slower is at rest){self._move_advice}"
            )
        lo, hi = np.quantile(a, self.quantiles)
        lo = max(lo, hi * 1e-4)
        cands = (
            np.geomspace(lo, hi, int(self.n_candidates))
            if around is None
            else near_candidates(around, lo, hi)
        )
        bounds = self.bounds
        columns = self._columns
        if sampling is None:
            s = sample_stride(len(dq))
            d_s, F_s = dq[s], F[s]

            def cost(shape):
                return bounded_lsq(columns(d_s, shape), F_s, bounds)[1]
        else:
            d_w, F_w = sampling.window_of(dq), F[sampling.search_rows]
            speeds = self._speeds(d_w)
            k = len(bounds)

            def cost(shape):
                Ab = np.empty((k + 1, len(F_w)))  # the filtered columns and F_w, transposed
                sampling.search_into(self._rows(speeds, shape), Ab[:k])
                Ab[k] = F_w
                return bounded_solve(*compress_rows(Ab), bounds)[1]

        shape, sse = shape_search(cost, cands, refine=self._refine)
        coef, rss = self._fit_columns(lambda v: columns(v, shape), dq, F, sampling, bounds)
        self.candidates_ = cands
        self.candidate_sse_ = sse
        self._set(np.append(coef, shape), rss, len(F))

    def columns(self, dq):
        return self._columns(dq, self.coef_[-1])

    def _speeds(self, dq: NDArray[np.float64]) -> Any:
        """What :meth:`_rows` needs of the search window's velocities (computed once per search)."""
        return dq

    def _rows(self, speeds: Any, shape: float) -> NDArray[np.float64]:
        """The columns at ``shape`` on the search window, transposed: (k, len(window))."""
        return np.ascontiguousarray(self._columns(speeds, shape).T)


_STATIC_PAIRS = ((0, 5), (1, 6))  # the seed model's (Coulomb, static level) coefficients, per direction


def _fastest(dq: NDArray[np.float64], dq_k: NDArray[np.float64]) -> float:
    """The fastest speed a fit saw (rad/s), over the full-rate and the kept samples.

    A seed model's viscous terms ``kv2 dq |dq|`` and ``kv3 dq^3`` are fitted over the training speeds and
    grow as a square and a cube beyond them: on a double pendulum whose held-out motion ran 25 % faster
    than its excitation, joint 1's friction came out 10-25 % high there (1.12 times the held-out RMS of
    OLS with linear friction).  Beyond this speed they continue as their secants through zero, a straight
    line that meets them at it."""
    return float(max(np.abs(dq).max(initial=0.0), np.abs(dq_k).max(initial=0.0)))


class SeedFriction(ShapedFriction):
    """The paper's friction model (METHOD.md section 2): low/high-speed split at a threshold lambda.

    Above the threshold (``|dq| >= lambda``)::

        F = kc+ + kv1 dq + kv2 dq |dq| + kv3 dq^3      (dq > 0)
        F = -kc- + kv1 dq + kv2 dq |dq| + kv3 dq^3     (dq < 0)

    Coulomb per direction, viscous odd in ``dq`` (``kv2 dq |dq|``: friction opposes motion).  Below it
    (ours: the paper leaves the form open) a straight line joins the static level ``+-ks+-`` at zero
    speed to the high-speed curve at ``+-lambda``, so the model is continuous at ``+-lambda``; with
    ``ks > kc`` it is the low-speed negative slope (Stribeck-like).  All seven coefficients are
    non-negative.  Beyond the fastest training speed ``vmax`` (ours) the square and cube go on as their
    secants, ``kv2 vmax dq`` and ``kv3 vmax^2 dq``: a polynomial fitted over the training speeds is not
    extrapolated as one (:func:`_fastest`).

    ``lambda`` comes from the modified Lawson-Hanson search: for each candidate (quantiles of
    ``|dq|``), the coefficients by non-negative least squares (:func:`scipy.optimize.nnls`); the
    candidate with the least squared error wins, refined by a golden-section search between its
    neighbours; then the final coefficients on all samples.

    Parameters
    ----------
    n_candidates : int
        Candidate thresholds (geometrically spaced between the quantiles ``quantiles`` of ``|dq|``).
    quantiles : tuple of float
        Range of the candidates as quantiles of ``|dq|``.  At least 1 % of the moving samples lie
        below the threshold by default: with fewer, the static levels are free to fit the few samples
        of the velocity reversals (on 10 s of simulated data: a threshold of 0.001 rad/s with static
        levels of 100-500 N m, and held-out errors three times larger).
    """

    name = "seed"
    coef_names = ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks_pos", "ks_neg", "lam")
    bounds = (0.0,) * 7
    static_ratio: ClassVar[float] = 3.0
    """Most a static level may exceed its Coulomb level by (``ks <= static_ratio kc``); beyond it the
    static level is held at the Coulomb level (``ks = kc``, no Stribeck excess in that direction) and the
    others are fitted again.

    Below a small threshold the static column lives on the few samples of the velocity reversals, and
    after the torque's filter it is a short blip: the fit is then free to put a static level of many times
    the Coulomb level there, filling the reversals' timing errors rather than any friction (12.3 N m against
    1.6 at a threshold of 0.002 rad/s on a simulated xArm 7 whose friction was Coulomb and viscous alone; 5.4
    times on a Unitree Z1's wrist), which a motion with other reversals turns into errors of several N m
    (2.5 and 1.8 times the held-out RMS of OLS with linear friction).  Measured stiction stays within
    1.5-2 times the Coulomb level; on the TX40 and the Panda the fitted static levels are below their
    Coulomb levels on every joint."""

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.01, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    _columns = staticmethod(_seed_columns)
    _speeds = staticmethod(_SeedSpeeds)  # type: ignore[assignment]
    _rows = staticmethod(_seed_rows)  # type: ignore[assignment]

    @property
    def tied_(self) -> tuple[bool, bool]:
        """Whether ``ks+ = kc+`` and ``ks- = kc-`` are held (the static level not told apart); the model
        file records it (``ks_pos_held``, ``ks_neg_held``; files written before the rule held none)."""
        return self.__dict__.get("_tied") or (False, False)

    @property
    def vmax_(self) -> float:
        """The fastest training speed (rad/s): beyond it the viscous terms continue as a straight line
        (:meth:`columns`); the model file records it (``vmax``; files written before: no limit)."""
        return float(self.__dict__.get("_vmax", np.inf))

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out["coef"]["ks_pos_held"], out["coef"]["ks_neg_held"] = (float(t) for t in self.tied_)
        if np.isfinite(self.vmax_):
            out["coef"]["vmax"] = self.vmax_
        return out

    def _restore(self, coef: dict[str, Any]) -> None:
        """Read what :meth:`to_dict` wrote beside the coefficients (the held static levels, the speed limit)."""
        self._tied = (bool(coef.get("ks_pos_held", 0.0)), bool(coef.get("ks_neg_held", 0.0)))
        self._vmax = float(coef.get("vmax", np.inf))

    @property
    def _linear(self) -> tuple[int, ...]:  # type: ignore[override]
        tied = self.tied_
        return (0, 1, 2, 3, 4, *(st for (_, st), held in zip(_STATIC_PAIRS, tied, strict=True) if not held))

    def merged(self, cols: Sequence[Any]) -> list[Any]:
        """The seven columns (arrays, or symbols for the C export) in the order of :meth:`linear_coef`: a
        held static level's column added to its Coulomb column, and dropped."""
        cols = list(cols)
        for (c, st), held in zip(_STATIC_PAIRS, self.tied_, strict=True):
            if held:
                cols[c] = cols[c] + cols[st]
        return [cols[k] for k in self._linear]

    def columns(self, dq):
        A = self._columns(dq, self.coef_[-1])
        vmax = self.vmax_
        fast = np.abs(dq) > vmax
        if fast.any():  # beyond the training speeds: dq |dq| and dq^3 go on as their secants, vmax dq, vmax^2 dq
            A = A.copy()
            A[fast, 3] = vmax * dq[fast]
            A[fast, 4] = vmax**2 * dq[fast]
        return np.column_stack(self.merged(A.T)) if any(self.tied_) else A

    def set_linear(self, coef: ArrayLike) -> None:
        super().set_linear(coef)
        new = self.coef_.copy()
        for (c, st), held in zip(_STATIC_PAIRS, self.tied_, strict=True):
            if held:
                new[st] = new[c]
        self.coef_ = new

    def _past_cap(self, c: NDArray[np.float64]) -> tuple[bool, bool]:
        """Per direction, whether the static level in ``coef_``-ordered ``c`` exceeds :attr:`static_ratio`
        times its Coulomb level."""
        pos, neg = (bool(c[st] > self.static_ratio * c[k] + 1e-12) for k, st in _STATIC_PAIRS)
        return pos, neg

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        self._tied = (False, False)
        self._vmax = _fastest(dq, dq_k)
        self.__dict__.pop("_filtered_basis", None)  # an earlier fit's
        super()._fit(dq, F, dq_k, sampling, around)
        A = self.__dict__.get("_filtered_basis")
        if A is None:
            A = self._columns(dq if sampling is None else dq_k, self.coef_[-1])
        c = self.coef_
        held = self._past_cap(c)
        if not any(held):
            return
        self._tied = held
        merged = np.column_stack(self.merged(A.T))
        coef, rss = bounded_lsq(merged, F, self.bounds[: merged.shape[1]])
        self.set_linear(coef)  # the held static levels follow their Coulomb levels
        if sampling is not None:
            self._filtered_basis = merged
        self._set(self.coef_, rss, len(F))

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("Stribeck friction", "direction-dependent Coulomb friction", "nonlinear viscous friction")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        left = _present(
            ("Stribeck friction", c["ks_pos"] != c["kc_pos"] or c["ks_neg"] != c["kc_neg"]),
            ("direction-dependent Coulomb friction", c["kc_pos"] != c["kc_neg"]),
            ("nonlinear viscous friction", c["kv2"] > 0 or c["kv3"] > 0),
        )
        return c["kv1"], 0.5 * (c["kc_pos"] + c["kc_neg"]), left


class SharedSeedFriction(SeedFriction):
    """The seed model with one static level for both directions (``ks+ = ks-``), the rest as
    :class:`SeedFriction`: Coulomb per direction, the same threshold search, the same cap of the static
    level (a direction whose shared level exceeds ``static_ratio`` times its Coulomb level is held at it,
    and the other direction keeps a static level of its own).

    The default pipeline takes it instead of the seed model when the recording's two folds hold one
    motion (:func:`dynid.identify.pipeline.one_motion`).  A static level is seen only at the velocity
    reversals, and a recording that repeats one excitation reverses each joint at the same few
    configurations in every period: a level per direction then also takes the model's error at those
    configurations (gravity, for a shoulder), which another motion, reversing elsewhere, does not share.
    On the unseen-arms benchmark's one-excitation runs (``benchmarks/unseen_arms_benchmark.py``), the default's
    worst joint against dynid's OLS with linear friction went 1.15 -> 0.95 (UR3), 1.24 -> 0.99 (Z1) and 0.99 ->
    0.95 (xArm 7), and 1.39 -> 1.57 (xArm 7, Stribeck friction: its Coulomb levels took the asymmetry) and
    1.08 -> 1.16 (Z1, Stribeck friction: the mixture on joint 4); the gains where the seed friction is right
    (UR10 0.74, UR3 0.97 with Stribeck friction) stayed: 7 of 10 cases within 1.05 instead of 5.  On the
    TX40's recording, whose halves are two motions, a shared level predicted the held-out run 6-13 % worse on
    joints 2 and 4: where the reversals vary, the levels per direction keep their meaning, and the seed model
    is used.
    """

    name = "seed_shared"

    def _sharing(self) -> bool:
        return bool(self.__dict__.get("_shared", False))

    @property
    def shared_(self) -> bool:
        """Whether one static level serves both directions (False when a direction's level is held at its
        Coulomb level); the model file records it (``ks_shared``)."""
        return self._sharing()

    @property
    def bounds(self) -> tuple[float, ...]:  # type: ignore[override]
        return (0.0,) * (6 if self._sharing() else 7)

    def _columns(self, dq, shape):  # type: ignore[override]
        A = _seed_columns(dq, shape)
        return np.column_stack([A[:, :5], A[:, 5] + A[:, 6]]) if self._sharing() else A

    def _rows(self, speeds, shape):  # type: ignore[override]
        A = _seed_rows(speeds, shape)
        return np.vstack([A[:5], A[5] + A[6]]) if self._sharing() else A

    @property
    def _linear(self) -> tuple[int, ...]:  # type: ignore[override]
        return (0, 1, 2, 3, 4, 5) if self._sharing() else super()._linear

    def merged(self, cols: Sequence[Any]) -> list[Any]:
        if not self._sharing():
            return super().merged(cols)
        cols = list(cols)
        return [*cols[:5], cols[5] + cols[6]]

    def set_linear(self, coef: ArrayLike) -> None:
        super().set_linear(coef)
        if self._sharing():
            new = self.coef_.copy()
            new[6] = new[5]
            self.coef_ = new

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out["coef"]["ks_shared"] = float(self._sharing())
        return out

    def _restore(self, coef: dict[str, Any]) -> None:
        super()._restore(coef)
        self._shared = bool(coef.get("ks_shared", 0.0))

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        self._tied = (False, False)
        self._shared = True
        self._vmax = _fastest(dq, dq_k)
        self.__dict__.pop("_filtered_basis", None)  # an earlier fit's
        ShapedFriction._fit(self, dq, F, dq_k, sampling, around)
        c = self.coef_  # kc+, kc-, kv1, kv2, kv3, ks, lam
        self.coef_ = np.concatenate([c[:6], c[5:6], c[6:]])
        c = self.coef_
        held = self._past_cap(c)
        if not any(held):
            return
        # a direction whose shared level passes its cap is held at its Coulomb level; the other keeps a level
        # of its own, held too if that passes its cap (refitted until no level is past it)
        self._shared = False
        A = _seed_columns(dq, c[-1])
        if sampling is not None:
            A = sampling.full(A)
        while True:
            self._tied = held
            merged = np.column_stack(self.merged(A.T))
            coef, rss = bounded_lsq(merged, F, (0.0,) * merged.shape[1])
            self.set_linear(coef)
            c = self.coef_
            past = self._past_cap(c)
            more = (held[0] or past[0], held[1] or past[1])
            if more == held:
                break
            held = more
        if sampling is not None:
            self._filtered_basis = merged
        self._set(self.coef_, rss, len(F))


class StribeckFriction(ShapedFriction):
    """``F = sign(dq) (fc + (fs - fc) exp(-(dq / vs)^2)) + fv dq + fo``, ``fc, fs, fv >= 0``, ``vs > 0``.

    ``vs`` (rad/s) by a search over quantiles of ``|dq|`` with the other coefficients by bounded linear
    least squares.

    Parameters
    ----------
    n_candidates : int
        Candidate Stribeck velocities.
    quantiles : tuple of float
        Their range as quantiles of ``|dq|``.
    """

    name = "stribeck"
    coef_names = ("fc", "fs", "fv", "fo", "vs")
    _linear = (0, 1, 2, 3)
    bounds = (0.0, 0.0, 0.0, -np.inf)

    _search_label = "Stribeck"
    _refine = False

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.002, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    @staticmethod
    def _columns(dq, vs):
        e = np.exp(-((dq / vs) ** 2))
        sg = direction(dq)
        return np.column_stack([sg * (1.0 - e), sg * e, dq, np.ones_like(dq)])

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("friction offset", "Stribeck friction")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        left = _present(("friction offset", abs(c["fo"]) > 0), ("Stribeck friction", abs(c["fs"] - c["fc"]) > 0))
        return max(c["fv"], 0.0), max(c["fc"], 0.0), left


class SigmoidFriction(FrictionModel):
    """``F = phi1 / (1 + exp(-phi2 (dq + phi3))) - phi1 / (1 + exp(-phi2 phi3))`` (Gaz et al. 2019).

    ``phi1`` (N m) scales, ``phi2`` (s/rad) sets the steepness, ``phi3`` (rad/s) shifts; ``F(0) = 0``.
    Fitted by variable projection (``phi1`` linear) and :func:`scipy.optimize.least_squares` on
    ``(log phi2, phi3)`` from a few starts.  On filtered data the shape ``(phi2, phi3)`` comes from
    the unfiltered fit at the kept samples and ``phi1`` is then refitted on the filtered shape.

    Parameters
    ----------
    max_samples : int
        Samples used in the nonlinear fit (evenly strided).
    """

    name = "sigmoid"
    coef_names = ("phi1", "phi2", "phi3")
    _linear = (0,)
    bounds = (-np.inf,)
    _min_samples = 10

    def __init__(self, *, max_samples: int = 20_000) -> None:
        self.max_samples = max_samples

    @staticmethod
    def _shape(dq, phi2, phi3):
        from scipy.special import expit  # here: the other models' paths pay no scipy.special import (50 ms)

        return expit(phi2 * (dq + phi3)) - expit(phi2 * phi3)

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        s = sample_stride(len(dq_k), int(self.max_samples))
        d, f = dq_k[s], F[s]
        scale = float(np.median(np.abs(d[d != 0]))) if np.any(d != 0) else 1.0

        def resid(z):
            g = self._shape(d, np.exp(z[0]), z[1])
            gg = float(g @ g)
            phi1 = float(g @ f) / gg if gg > 0 else 0.0
            return phi1 * g - f

        starts = [
            np.array([np.log(k2 / scale), k3 * scale]) for k2 in (1.0, 10.0, 100.0) for k3 in (0.0, 0.3, -0.3)
        ]
        from scipy.optimize import least_squares

        fits = [least_squares(resid, z0, method="lm", max_nfev=200) for z0 in starts]
        best = min(fits, key=lambda sol: sol.cost)  # the first of the least cost, as before
        phi2, phi3 = float(np.exp(best.x[0])), float(best.x[1])
        coef, rss = self._fit_columns(
            lambda v: self._shape(v, phi2, phi3)[:, None], dq, F, sampling, self.bounds
        )
        self._set([float(coef[0]), phi2, phi3], rss, len(F))

    def columns(self, dq):
        return self._shape(dq, self.coef_[1], self.coef_[2])[:, None]

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("sigmoid friction shape")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        return 0.0, 0.5 * abs(c["phi1"]), ("sigmoid friction shape",)
