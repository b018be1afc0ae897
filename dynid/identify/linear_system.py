"""The linear identification system: from a dataset to a compressed, stacked least-squares problem.

Layer 1 of the identification (METHOD.md section 4) solves ``tau = W x`` with ``W`` the regressor
stacked over ``m`` samples (``m n`` rows) and ``x`` the identified parameters
(:mod:`dynid.identify.columns`).  This module builds that system once, without ever holding ``W``
twice in memory, and compresses it to a small triangular factor from which every weighting (OLS,
WLS, GLS, IRLS) is solved exactly (:meth:`LinearSystem.solve`, a :class:`WeightedSolution`).

The data path
-------------
1. :func:`dynid.data.preparation.prepare`: the states at full rate (zero-phase Butterworth on
   ``q``, central differences for missing ``dq`` / ``ddq``; :func:`dynid.data.preprocess.preprocess`),
   the rows kept after trimming and decimation, and the torque filter.
2. The regressor columns through the compiled batch path (:func:`dynid.symbolic.export.compiled_functions`),
   a chunk of samples at a time, written once into one buffer ``Z`` of shape (m, c): one column per
   structurally non-zero (joint row, parameter) pair of the regressor, plus the n torques.  For the
   UR5 with friction and armature, c = 172 instead of the 6 x 60 + 6 = 366 of the dense layout.
3. Parallel filtering (DIAGNOSIS.md section 3): the same low-pass on every column of ``Z``, torque
   included, in place.
4. One pass of blocked Householder QR over the kept rows: ``Z = Q R_Z``.  ``R_Z`` (c x c) holds all
   that least squares needs: for any joint-noise covariance ``Omega = L L^T`` the whitened stacked
   system ``(I_m (x) L^-1) [W | tau]`` has the same R factor as the small matrix
   ``[R_Z T_1; ...; R_Z T_n]`` (n c rows), with ``T_i`` the (c x (p + 1)) map from the columns of
   ``Z`` to row i of the whitened regressor and torque.  No normal equations are formed.

The preprocessing settings and the column set live in :mod:`dynid.data.preparation` and
:mod:`dynid.identify.columns`; their public names are importable from here too.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from dynid._threads import JOINT_THREADS, single_blas_thread
from dynid.data.dataset import Dataset
from dynid.data.preparation import AUTO_CUTOFF_HZ, Prepared, Preprocessing, prepare, still_joints
from dynid.data.preprocess import filter_order, filter_padding, filtfilt_rows, kept_rows
from dynid.exceptions import DataError, IdentificationError, ShapeError
from dynid.identify._qr import r_factor
from dynid.identify.columns import (
    CHUNK_SAMPLES,
    EXTRA_KINDS,
    ColumnSet,
    column_set,
    compiled_base_regressor,
    linear_torque,
)
from dynid.identify.effect_terms import EffectColumns

__all__ = [
    "AUTO_CUTOFF_HZ",
    "EXTRA_KINDS",
    "RANK_TOL",
    "ColumnSet",
    "LinearSystem",
    "Prepared",
    "Preprocessing",
    "WeightedSolution",
    "build_system",
    "check_rank",
    "column_set",
    "compiled_base_regressor",
    "describe_joints",
    "forget_shared",
    "linear_torque",
    "prepare",
    "sharing_systems",
    "still_joints",
]

RANK_TOL = 1e-10
"""Relative singular value (of the column-normalised weighted regressor) below which a direction of
the parameters counts as not excited by the data."""
_FILTER_COLUMNS = 16  # columns of Z filtered at once (16 x 360,000 samples: 46 MB of temporaries)
KEPT_BYTES = 256 * 2**20
"""The data matrix's budget at the kept rows: a longer recording is identified on one sample in ``D``
(:func:`thinned_for_memory`)."""
FULL_RATE_BYTES = 512 * 2**20
"""A data matrix at full rate up to this size is filled and filtered whole; a longer recording's is built
a block at a time, only its kept rows held (see :func:`_kept_data_matrix`)."""


@dataclass(frozen=True, eq=False)
class WeightedSolution:
    """Least squares of the whitened system: ``min || L^-1 (tau - W x) ||^2`` over all samples.

    Attributes
    ----------
    x : ndarray, shape (p,)
        Estimate.
    R : ndarray, shape (p, p)
        Upper-triangular factor of the whitened stacked regressor.
    rhs : ndarray, shape (p,)
        ``Q^T`` times the whitened torque: ``|| W~ x - y~ ||^2 = || R x - rhs ||^2 + rss``.
    rss : float
        Whitened residual sum of squares at ``x``.
    whitener : ndarray, shape (n, n)
        ``L^-1`` used.
    """

    x: NDArray[np.float64]
    R: NDArray[np.float64]
    rhs: NDArray[np.float64]
    rss: float
    whitener: NDArray[np.float64]


@dataclass(eq=False)
class LinearSystem:
    """The stacked identification system of one dataset, compressed (see the module docstring).

    Build it with :func:`build_system`; every estimator of :mod:`dynid.identify.estimators` can fit
    it (so several methods share one pass over the data).

    Attributes
    ----------
    columns : ColumnSet
        The identified parameters.
    prepared : Prepared
        States, kept rows and filter.
    R_Z : ndarray, shape (c, c)
        R factor of the data matrix ``Z`` (regressor entries and torques) over the kept rows.
    z_joint : ndarray of int, shape (c,)
        Joint row (0-based) of each column of ``Z``.
    z_param : ndarray of int, shape (c,)
        Identified parameter of each column of ``Z``; -1 for the torque columns.
    Z : ndarray, shape (m, c) or None
        The (filtered) data matrix at the kept rows, kept until :meth:`release` for per-sample residuals.
    derived : dict
        Arrays taken from ``Z`` by the later layers, kept for reuse until :meth:`release` (e.g. the
        refined parameters' columns per joint, which both refinements of a default identification use).
    """

    columns: ColumnSet
    prepared: Prepared
    R_Z: NDArray[np.float64]
    z_joint: NDArray[np.intp]
    z_param: NDArray[np.intp]
    Z: NDArray[np.float64] | None = field(default=None, repr=False)
    derived: dict = field(default_factory=dict, repr=False)
    shared: bool = field(default=False, repr=False)

    @property
    def m(self) -> int:
        """Samples (kept rows)."""
        return self.prepared.m

    @property
    def n(self) -> int:
        """Joints."""
        return self.columns.n

    @property
    def p(self) -> int:
        """Identified parameters."""
        return self.columns.p

    def release(self) -> None:
        """Drop the full data matrix (the compressed factor stays; per-sample methods stop working)."""
        self.Z = None
        if not self.shared:  # a system handed out by :func:`sharing_systems` keeps them for the others
            self.derived.clear()

    # -------------------------------------------------------------- weighted solves
    def stacked(self, whitener: NDArray[np.float64]) -> NDArray[np.float64]:
        """The stacked small matrix ``[R_Z T_1; ...; R_Z T_n]``, shape (n c, p + 1).

        Block ``i`` (rows ``i c .. (i + 1) c``) holds whitened joint ``i``: its first ``p`` columns
        have the same Gram matrix as that joint's rows of the whitened regressor, its last column is
        the whitened torque.

        Parameters
        ----------
        whitener : ndarray, shape (n, n)
            ``L^-1`` with ``Omega = L L^T`` the joint-noise covariance (identity for OLS).
        """
        c, n, p = len(self.z_joint), self.n, self.p
        out = np.empty((n * c, p + 1))
        reg = self.z_param >= 0
        for i in range(n):
            T = np.zeros((c, p + 1))
            T[np.flatnonzero(reg), self.z_param[reg]] = whitener[i, self.z_joint[reg]]
            T[np.flatnonzero(~reg), p] = whitener[i, self.z_joint[~reg]]
            out[i * c : (i + 1) * c] = self.R_Z @ T
        return out

    def whitened(
        self, whitener: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """R factor of the whitened system: ``(R (p, p), rhs (p,), rss)`` with rss the minimal residual.

        Parameters
        ----------
        whitener : ndarray, shape (n, n)
            ``L^-1`` with ``Omega = L L^T`` the joint-noise covariance (identity for OLS).
        """
        p = self.p
        R_aug = r_factor(self.stacked(whitener), overwrite=True)[: p + 1]
        if R_aug.shape[0] < p + 1:  # fewer stacked rows than columns (tiny data): pad
            R_aug = np.vstack([R_aug, np.zeros((p + 1 - R_aug.shape[0], p + 1))])
        return R_aug[:p, :p], R_aug[:p, p], float(R_aug[p, p] ** 2)

    def solve(self, whitener: NDArray[np.float64]) -> WeightedSolution:
        """Weighted least squares ``min || L^-1 (tau - W x) ||^2`` over all samples.

        Parameters
        ----------
        whitener : ndarray, shape (n, n)
            ``L^-1`` with ``Omega = L L^T`` the joint-noise covariance (identity for OLS).

        Returns
        -------
        WeightedSolution

        Raises
        ------
        IdentificationError
            The data do not excite some parameters (see :func:`check_rank`).
        """
        R, rhs, rss = self.whitened(whitener)
        check_rank(self, R)
        x = scipy.linalg.solve_triangular(R, rhs, check_finite=False)
        return WeightedSolution(x=x, R=R, rhs=rhs, rss=rss, whitener=whitener)

    def _model_map(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None) -> NDArray[np.float64]:
        """(c, n): the data matrix's columns to the model torque ``W x`` per joint (torque columns 0)."""
        xm = x if mask is None else np.where(mask, x, 0.0)
        reg = np.flatnonzero(self.z_param >= 0)
        C = np.zeros((len(self.z_joint), self.n))
        C[reg, self.z_joint[reg]] = xm[self.z_param[reg]]
        return C

    def residual_matrix(
        self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None
    ) -> NDArray[np.float64]:
        """``E^T E`` (n x n) of the residuals ``E = tau - W x`` over the kept rows (N^2 m^2).

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters in the model.
        """
        C = -self._model_map(x, mask)  # the residual tau - W x: minus the model ...
        tau = np.flatnonzero(self.z_param < 0)
        C[tau, self.z_joint[tau]] = 1.0  # ... plus each joint's torque column
        G = self.R_Z @ C
        return G.T @ G

    def rms(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """Residual RMS per joint (N m) over the kept rows.

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters in the model.
        """
        return np.sqrt(np.maximum(np.diag(self.residual_matrix(x, mask)), 0.0) / self.m)

    # -------------------------------------------------------------- per-sample values
    def data_matrix(self) -> NDArray[np.float64]:
        """The (filtered) data matrix ``Z`` at the kept rows, (m, c); an error once released."""
        if self.Z is None:
            raise IdentificationError(
                "the data matrix of this system was released; per-sample values need it: build the system "
                "again with build_system(...) or call this before release()"
            )
        return self.Z

    def tau(self) -> NDArray[np.float64]:
        """Torque at the kept rows, treated like the regressor (filtered with parallel filtering): (m, n)."""
        Z = self.data_matrix()
        cols = np.flatnonzero(self.z_param < 0)
        order = np.argsort(self.z_joint[cols])
        return np.ascontiguousarray(Z[:, cols[order]])

    def predict(self, x: NDArray[np.float64], mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """``W x`` at the kept rows (N m), (m, n), with the regressor treated like the torque.

        Parameters
        ----------
        x : ndarray, shape (p,)
            Parameters.
        mask : ndarray of bool, shape (p,), optional
            Use only these parameters.
        """
        Z = self.data_matrix()
        C = self._model_map(x, mask)
        out = np.empty((Z.shape[0], self.n))
        for a in range(0, Z.shape[0], CHUNK_SAMPLES):
            out[a : a + CHUNK_SAMPLES] = Z[a : a + CHUNK_SAMPLES] @ C
        return out


def _fill_Z(
    columns: ColumnSet,
    prepared: Prepared,
    z_cols: list[tuple[int, int]],
    effect_values=None,
    span: slice | NDArray[np.intp] | None = None,
) -> NDArray[np.float64]:
    """The data matrix at full rate, (M, c), or at the samples ``span`` only (a range, or rows when
    nothing is filtered): regressor entries (joint, parameter) then torques."""
    robot, nb, n = columns.robot, columns.n_base, columns.n
    span = slice(0, len(prepared.t)) if span is None else span
    q, dq, ddq = prepared.q[span], prepared.dq[span], prepared.ddq[span]
    M = len(q)
    c = len(z_cols) + n
    Z = np.empty((M, c))
    link = [(k, j * nb + pi) for k, (j, pi) in enumerate(z_cols) if pi < nb]
    link_z = np.array([k for k, _ in link], dtype=np.intp)
    link_flat = np.array([f for _, f in link], dtype=np.intp)
    p_extra = nb + len(columns.extras)
    extra = [(k, j, pi - nb) for k, (j, pi) in enumerate(z_cols) if nb <= pi < p_extra]
    effect = [(k, j, pi - p_extra) for k, (j, pi) in enumerate(z_cols) if pi >= p_extra]
    for a in range(0, M, CHUNK_SAMPLES):
        s = slice(a, min(a + CHUNK_SAMPLES, M))
        Yb = compiled_base_regressor(robot, q[s], dq[s], ddq[s])
        Z[s, link_z] = Yb.reshape(Yb.shape[0], -1)[:, link_flat]
    if extra:
        E = columns.extra_columns(dq, ddq)
        weights = columns.extra_weights
        for k, j, e in extra:
            Z[:, k] = E[:, e] * weights[j, e]
    for k, j, e in effect:
        Z[:, k] = effect_values[span, j, e]
    Z[:, len(z_cols) :] = prepared.tau[span]
    return Z


def _check_runs(prepared: Prepared, sos: NDArray[np.float64]) -> None:
    pad = filter_padding(sos)
    for r, run in enumerate(prepared.runs):
        if run.stop - run.start <= pad:
            raise DataError(
                f"run {r} has {run.stop - run.start} samples, too short for an order-{filter_order(sos)} zero-phase "
                f"filter (needs more than {pad}); drop that run or record longer"
            )


def _filter_in_place(Z: NDArray[np.float64], prepared: Prepared, runs: Sequence[slice] | None = None) -> None:
    """Low-pass every column of Z in place with the torque's filter, run by run."""
    sos = prepared.sos
    if sos is None:
        return
    _check_runs(prepared, sos)
    for run in prepared.runs if runs is None else runs:

        def chunk(a: int, run: slice = run) -> None:
            cols = slice(a, min(a + _FILTER_COLUMNS, Z.shape[1]))
            Z[run, cols] = filtfilt_rows(sos, Z[run, cols].T).T

        # scipy's filter releases the GIL: two chunks at once on 2 cores (the same values)
        with ThreadPoolExecutor(max_workers=JOINT_THREADS) as pool:
            list(pool.map(chunk, range(0, Z.shape[1], _FILTER_COLUMNS)))


def _kept_data_matrix(
    columns: ColumnSet, prepared: Prepared, z_cols: list[tuple[int, int]], effect_values=None
) -> NDArray[np.float64]:
    """The filtered data matrix at the kept rows, (m, c).

    A recording whose full-rate matrix fits :data:`FULL_RATE_BYTES` is filled and filtered whole,
    then its kept rows are moved to the front in place and the rest let go.  A longer one is filled
    and filtered a block of samples at a time, each block widened by :func:`filter_margin` on both
    sides inside its run (a zero-phase filter's response has died out to rounding beyond it), and
    only the block's kept rows are written: memory in the kept rows, not in the recording's length.
    """
    rows, M, c = prepared.rows, len(prepared.t), len(z_cols) + columns.n
    sos = prepared.sos
    if M * c * 8 <= FULL_RATE_BYTES or sos is None:
        if sos is None and rows.size < M:  # nothing to filter: only the kept rows are evaluated
            Z = np.empty((len(rows), c))
            for a in range(0, len(rows), CHUNK_SAMPLES):
                r = rows[a : a + CHUNK_SAMPLES]
                Z[a : a + len(r)] = _fill_Z(columns, prepared, z_cols, effect_values, r)
            return Z
        Z = _fill_Z(columns, prepared, z_cols, effect_values)
        _filter_in_place(Z, prepared)
        for a in range(0, len(rows), CHUNK_SAMPLES):  # rows[i] >= i: a block never reads what was moved
            r = rows[a : a + CHUNK_SAMPLES]
            Z[a : a + len(r)] = Z[r]
        Z.resize((len(rows), c), refcheck=False)  # nothing else refers to Z: the tail is let go
        return Z
    _check_runs(prepared, sos)
    margin = filter_margin(prepared)
    block = max(4 * margin, FULL_RATE_BYTES // (16 * 8 * c))
    Z = np.empty((len(rows), c))
    for run in prepared.runs:
        for a in range(run.start, run.stop, block):
            b = min(a + block, run.stop)
            lo, hi = np.searchsorted(rows, [a, b])
            if lo == hi:
                continue
            span = slice(max(run.start, a - margin), min(run.stop, b + margin))
            part = _fill_Z(columns, prepared, z_cols, effect_values, span)
            _filter_in_place(part, prepared, [slice(0, len(part))])
            Z[lo:hi] = part[rows[lo:hi] - span.start]
    return Z


def thinned_for_memory(prepared: Prepared, c: int, budget: int | None = None) -> Prepared:
    """The prepared samples with one kept in ``D``, when their data matrix would exceed the budget.

    A recording of half an hour at 1 kHz holds two million samples: their data matrix (``c`` columns,
    172 for a 6-joint arm with friction and armature) would take 2.75 GB.  After the low-pass the
    torque carries nothing above the cut-off, and its noise is correlated over about
    ``fs / (2 cutoff)`` samples, so one sample in ``D`` (the least ``D`` that fits the budget, the
    decimated rate kept above 2.5 times the highest cut-off) holds nearly the same information; the
    standard deviations count the samples kept (:attr:`Prepared.noise_correlation`).  The states and
    the filter stay at the full rate (the derivatives are taken there).  Unchanged under the budget.

    Parameters
    ----------
    prepared : Prepared
        The prepared recording (its ``decimate`` setting 1).
    c : int
        Columns of the data matrix.
    budget : int, optional
        Bytes (default :data:`KEPT_BYTES`).

    Returns
    -------
    Prepared
        With ``rows`` thinned, ``settings["decimate"]`` the factor and ``settings["decimate_rule"]`` the
        sentence that says why; or ``prepared`` itself.
    """
    budget = KEPT_BYTES if budget is None else budget
    size = prepared.m * c * 8
    if size <= budget:
        return prepared
    settings = prepared.settings
    D = math.ceil(size / budget)
    band = max((f for f in (settings["cutoff_hz"], settings["state_cutoff_hz"]) if f is not None), default=None)
    limit = "" if band is None else f", {prepared.fs / D / band:.3g} times the {band:.4g} Hz cut-off"
    if band is not None and D > int(0.4 * prepared.fs / band):
        D = max(1, int(0.4 * prepared.fs / band))
        limit = (
            f", 2.5 times the {band:.4g} Hz cut-off: no fewer samples keep the filtered torque's band, so the "
            f"matrix takes {size / D / 2**30:.2g} GB; split the recording to use less"
        )
    if D < 2:
        return prepared
    trim = math.ceil(settings["trim_s"] * prepared.fs - 1e-9)
    rows = kept_rows(prepared.runs, decimate=D, trim_samples=trim)
    rule = (
        f"identified on one sample in {D} ({prepared.fs / D:.4g} Hz{limit}): the {prepared.m:,} samples' data "
        f"matrix would take {size / 2**30:.2g} GB, more than the {budget / 2**20:.0f} MB dynid holds; "
        "--decimate N (N > 1) chooses another factor"
    )
    return replace(prepared, rows=rows, settings={**settings, "decimate": D, "decimate_rule": rule})


def filter_margin(prepared: Prepared) -> int:
    """Samples beyond which the prepared torque filter's zero-phase response has died out to rounding.

    ``40 fs / cutoff``: the order-5 Butterworth's slowest pole decays by ``exp(-2 pi 0.31 cutoff t)``,
    below 1e-30 after ``40 / cutoff`` seconds (:attr:`Prepared.noise_correlation` uses the same span).
    """
    cutoff = prepared.settings["cutoff_hz"]
    return int(np.ceil(40 * prepared.fs / cutoff)) + 64 if cutoff else 0


def _qr_rows(Z: NDArray[np.float64]) -> NDArray[np.float64]:
    """R factor (c x c) of ``Z`` by blocked Householder QR (one block in memory at a time)."""
    c = Z.shape[1]
    R = np.zeros((0, c))
    for a in range(0, Z.shape[0], CHUNK_SAMPLES):
        block = np.vstack([R, Z[a : a + CHUNK_SAMPLES]])
        R = r_factor(block, overwrite=True)[:c]
    if R.shape[0] < c:
        R = np.vstack([R, np.zeros((c - R.shape[0], c))])
    return R


_SHARED: contextvars.ContextVar[dict | None] = contextvars.ContextVar("dynid_shared_systems", default=None)


@contextlib.contextmanager
def sharing_systems() -> Iterator[None]:
    """Within this block, :func:`build_system` builds each system once and hands out copies.

    The default identification fits several pipelines on the same data (its cross-validation fits
    four candidates on each half of the recording, then the chosen one on the whole): they all take
    the same system of the same dataset (the same robot, preprocessing, friction and armature
    columns), so it is built once per dataset.  The copies share the data matrix, which nothing
    writes after :func:`build_system`, and the arrays derived from it, which are keyed by what they
    were computed from; the results are the same, bit for bit, as with a system built per fit.
    Systems with effect columns are built every time.  Everything is let go when the block ends.
    """
    token = _SHARED.set({})
    try:
        yield
    finally:
        _SHARED.reset(token)


def forget_shared(data: Dataset) -> None:
    """Let go of the systems :func:`sharing_systems` keeps for ``data`` (a later build builds again)."""
    shared = _SHARED.get()
    if shared:
        for key in [k for k, v in shared.items() if v[0] is data]:
            del shared[key]


def build_system(
    robot,
    data: Dataset,
    *,
    preprocessing: Preprocessing | None = None,
    friction: bool = True,
    armature: bool = True,
    keep_samples: bool = True,
    effects: EffectColumns | None = None,
) -> LinearSystem:
    """Build the compressed identification system of a dataset (the one expensive pass over the data).

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    data : Dataset
        ``t``, ``q``, ``tau`` and optionally ``dq``, ``ddq``.
    preprocessing : Preprocessing, optional
        Filtering, differentiation, trimming, decimation (default :class:`Preprocessing`).
    friction : bool
        Identify linear friction with the link parameters.
    armature : bool
        Identify the armature with the link parameters.
    keep_samples : bool
        Keep the filtered data matrix for per-sample residuals (layers 2 and 3 need them); False frees
        it at once.
    effects : EffectColumns, optional
        Effect terms identified with the other parameters (:mod:`dynid.identify.effect_terms`), their
        columns on this dataset's prepared grid.

    Returns
    -------
    LinearSystem

    Raises
    ------
    IdentificationError
        Fewer equations than parameters.
    DataError
        Malformed data, wrong joint count, bad filter settings.
    """
    shared = _SHARED.get()
    if shared is not None and (effects is None or not len(effects.names)):
        key: tuple = (id(data), id(robot), preprocessing, friction, armature)
        try:
            hash(key)
        except TypeError:  # unhashable settings: compared by their text
            key = (id(data), id(robot), repr(preprocessing), friction, armature)
        hit = shared.get(key)
        if hit is None or hit[0] is not data or hit[1] is not robot:
            system = _build(robot, data, preprocessing, friction, armature, None, True)
            hit = shared[key] = (data, robot, system)
        system = hit[2]
        return replace(system, Z=system.Z if keep_samples else None, shared=True)
    return _build(robot, data, preprocessing, friction, armature, effects, keep_samples)


def _build(robot, data, preprocessing, friction, armature, effects, keep_samples) -> LinearSystem:
    prepared = prepare(data, preprocessing, n_joints=robot.n)
    columns = column_set(robot, friction=friction, armature=armature)
    pre = preprocessing or Preprocessing()
    if pre.decimate == 1 and pre.thin:
        c = int(columns.pattern.sum()) + robot.n + (0 if effects is None else robot.n * len(effects.names))
        prepared = thinned_for_memory(prepared, c)
    values = None
    if effects is not None and len(effects.names):
        values = np.asarray(effects.values, dtype=np.float64)
        if values.shape != (len(prepared.t), robot.n, len(effects.names)):
            raise ShapeError(
                f"the effect columns have shape {values.shape}; expected {(len(prepared.t), robot.n, len(effects.names))} "
                "(the prepared samples, the joints, the coefficients): build them on this dataset's prepared states"
            )
        columns = columns.with_effects(effects.terms, effects.names, np.any(values != 0.0, axis=0))
    n, p = robot.n, columns.p
    m = prepared.m
    if m * n <= p or m < 2:
        raise IdentificationError(
            f"the data give {m} samples ({m * n} equations) after preprocessing for {p} parameters; "
            f"record more than {p // n + 1} samples (in practice at least {10 * p // n}), or trim/decimate less"
        )
    z_cols = [(j, k) for k in range(p) for j in range(n) if columns.pattern[j, k]]
    Z = _kept_data_matrix(columns, prepared, z_cols, values)
    with single_blas_thread():
        R_Z = _qr_rows(Z)
    z_joint = np.array([j for j, _ in z_cols] + list(range(n)), dtype=np.intp)
    z_param = np.array([k for _, k in z_cols] + [-1] * n, dtype=np.intp)
    return LinearSystem(
        columns=columns,
        prepared=prepared,
        R_Z=R_Z,
        z_joint=z_joint,
        z_param=z_param,
        Z=Z if keep_samples else None,
    )


def check_rank(system: LinearSystem, R: NDArray[np.float64]) -> None:
    """Raise an :class:`IdentificationError` naming the parameters the data do not excite.

    Parameters
    ----------
    system : LinearSystem
        The identification system.
    R : ndarray, shape (p, p)
        Upper-triangular factor of its weighted stacked regressor.
    """
    cols = system.columns
    norms = np.linalg.norm(R, axis=0)
    scale = norms.max(initial=0.0)
    zero = norms <= 1e-13 * max(scale, 1e-300)
    Rs = R / np.where(zero, 1.0, norms)
    Rs[:, zero] = 0.0
    _, sv, Vt = np.linalg.svd(Rs)
    small = sv <= RANK_TOL * max(sv[0], 1e-300)
    if not small.any():
        return
    null = Vt[small]
    weight = np.sqrt((null**2).sum(axis=0))
    involved = np.flatnonzero((weight > 0.05) | zero)
    names = [cols.names[k] for k in involved]
    rank = int((~small).sum())
    still = still_joints(system.prepared)
    links = sorted({int(cols.joints[k]) for k in involved})
    if still:
        hint = (
            f"{describe_joints(still)} never move{'s' if len(still) == 1 else ''} in the data: record a motion "
            f"that moves {describe_joints(still)} too, with varied velocity and acceleration"
        )
    else:
        hint = (
            f"record a richer motion of {describe_joints(links)} (larger, varied velocities and accelerations; "
            "an optimised excitation from 'dynid excite'), or identify without those terms"
        )
    raise IdentificationError(
        f"the data do not excite the base parameters {', '.join(names)} (the weighted regressor has rank {rank} "
        f"of {system.p}); {hint}"
    )


def describe_joints(joints: Sequence[int]) -> str:
    """'joint 6' or 'joints 5 and 6'."""
    js = [str(j) for j in joints]
    if len(js) == 1:
        return f"joint {js[0]}"
    return "joints " + ", ".join(js[:-1]) + " and " + js[-1]
