"""The default pipeline chosen from the recording: blocked cross-validation of a few candidates.

The paper's full pipeline (IRLS link parameters, its nonlinear friction, a Gaussian-mixture correction)
beats a plain fit on the arms it was tuned on and can lose to it on others: on the KUKA LWR4+, whose
pre-filtered torque sensors see little friction, ordinary least squares with linear friction predicts a
motion it has not seen better on every joint.  Which one a recording supports is a question the
recording can answer.  :func:`choose_pipeline` cuts the training recording in two folds
(:func:`folds`: its two contiguous halves, or, for a recording of several runs such as two excitations,
its runs), fits each candidate (:func:`candidates`, from the simplest to the richest) on one fold and
scores its prediction of the other, both ways; a candidate with a joint worse than ordinary least
squares with linear friction by more than :data:`JOINT_TOLERANCE` is out, and of the others the
simplest whose mean relative error is within :data:`PARSIMONY` of the best is taken (:func:`decide`), so
the default is not worse than dynid's simplest pipeline on that score beyond the resolution of two
folds.  Then :func:`gain_screen` and :func:`choose_gains` give a drive gain to the joints whose measured
torque reads a constant factor off the model's, where the folds confirm it.  Training data only; the
held-out recording is never seen.

Two halves of one excitation played several times hold the same motion, so they cannot show a pipeline
that fits that motion rather than the arm (:data:`PARSIMONY`); two recordings of different motions can.
Splitting such a recording by phase instead (the first against the second half of every period) was
tried and dropped: each half period holds states, often a velocity sign, that the other never sees, and
it refused pipelines that predict a new motion best.  :func:`one_motion` tells when the two folds hold
one motion, and the reason then says so, with the commands that design and use a second excitation.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._memory import give_back
from dynid._progress import advance, stage
from dynid.exceptions import DynidError
from dynid.identify.linear_system import sharing_systems

__all__ = [
    "BASELINE",
    "GAIN_GAIN",
    "GAIN_SCREEN",
    "JOINT_TOLERANCE",
    "ONE_MOTION",
    "PARSIMONY",
    "RATE_FACTOR",
    "RUN_BALANCE",
    "SAME_MOTION",
    "PipelineChoice",
    "candidates",
    "choose_gains",
    "choose_pipeline",
    "coarse_recording",
    "decide",
    "folds",
    "gain_screen",
    "one_motion",
]

BASELINE = ("ols", "linear", "off")
"""Ordinary least squares, linear friction, no correction: the pipeline every choice must match."""

JOINT_TOLERANCE = 0.05
"""How much worse than the baseline (relative cross-validated RMS) any joint of a chosen candidate may be.

The promise to a user is that no joint of the default predicts a motion it has not seen more than 5 %
worse than dynid's simplest pipeline; the veto holds the cross-validation to the same figure.  On the
TX40 the paper's pipeline scores at most 2.3 % worse than the baseline on any joint (joint 4) and 10 %
better in the mean, and predicts the held-out part better on all six; on the LWR4+ it scores 36 % worse
on one joint and loses on three held out."""

PARSIMONY = 0.05
"""The simplest candidate whose mean relative cross-validated error is within this of the best's is taken.

Two halves of a recording that repeats one motion (an excitation's periods) hold that motion twice: a
richer friction model fitted to its speed profile scores better there than on a motion of its own.  On
a simulated xArm 7 with Stribeck friction the paper's pipeline scored 31 % below the baseline on the
halves and predicted another trajectory up to 1.37 times worse on three joints, where IRLS with linear
friction stayed within 1.06 times.  A richer pipeline must earn its place by more than the halves'
optimism.  Two excitations, given as two runs, show that case for what it is (:func:`folds`)."""

GAIN_SCREEN = 0.10
"""A joint's drive gain is tried when it explains as much as this fall of one joint's RMS, in-sample.

A torque sensor or a current-to-torque constant a few percent off (joint 6 of the Panda recording reads
about 6 % more than any rigid body predicts) leaves a residual in proportion to the joint's own torque,
which the link parameters cannot take wholly, since each acts on several joints at once.  The screen
(:func:`gain_screen`) costs no fit: the gain's column lies in the span of the recording's system."""

GAIN_GAIN = 0.10
"""A screened drive gain is kept when refitting with it lowers its joint's cross-validated RMS this much.

The refit (:func:`choose_gains`) fits the chosen pipeline with the gains on each fold and scores the
other, as the candidates were scored; a gain that does not earn this much on its own joint is dropped,
and the gains are kept only if no joint ends more than :data:`JOINT_TOLERANCE` worse than without them."""

_MIN_HALF_SECONDS = 2.0  # folds shorter than this cannot score a motion (the full pipeline is kept)
_MIN_FOLD_ROWS = 64

ONE_MOTION = {
    "halves": "; its two halves hold one motion (most states of one lie on the other's path), so they cannot "
    "tell a pipeline fitted to that motion from one fitted to the arm: record a second excitation (dynid "
    "excite --trajectories 2 designs two that complement each other) and give both recordings (dynid "
    "identify --data A.csv B.csv) to choose on a motion not seen",
    "runs": "; its runs hold one motion (most states of one lie on the other's path: one excitation recorded "
    "again), so they cannot tell a pipeline fitted to that motion from one fitted to the arm: record a "
    "different excitation (dynid excite --trajectories 2 designs two that complement each other) and "
    "identify on both to choose on a motion not seen",
}
"""Said after the reason (:attr:`PipelineChoice.said`) when the folds hold one motion (:func:`one_motion`)."""

SAME_MOTION = 0.25
"""Two folds hold one motion when the median distance from a state of one to the nearest state of the
other is below this, in standard deviations of each angle and speed (:func:`one_motion`).

Measured on the decimated copies the pipeline scores: one motion 0.004-0.013 (the halves of one
excitation played six times on the five simulated arms of ``benchmarks/unseen_arms_benchmark.py``; the
halves of the LWR4+'s run 1, 0.008; its runs 1 and 2, one excitation recorded twice, 0.013); two motions
1.6-5.0 (two excitations on the same five arms; the LWR4+'s runs 1 and 3, 1.6; the halves of the Panda's
and the TX40's training recordings, 4.0-4.1)."""

RUN_BALANCE = 1.0 / 3.0
"""Runs become the folds when the smaller fold they make holds at least this share of the samples.

Whole runs are dealt to two folds, the longest first to the fold with fewer samples; a run that holds
most of the recording would leave the other fold too little to fit on, and the halves are used (as
they are when a fold of runs would last under two seconds or hold under 64 samples)."""

RATE_FACTOR = 10.0
"""The cross-validation fits the candidates at a rate of at least this many times the torque's cut-off.

A recording sampled far above its cut-off (the TX40 at 5 kHz for a 52 Hz cut-off, the Panda at 1 kHz for
15 Hz) carries nothing below the cut-off that one sample in ``D`` does not: after the low-pass the
torque's noise is correlated over about ``fs / (2 cutoff)`` samples, so ``D`` times fewer of them hold
the same information.  The candidates are scored on the recording low-passed at 0.8 of the lower rate's
Nyquist frequency and decimated (:func:`coarse_recording`), all of them alike; the chosen pipeline is
then fitted on the recording as it came."""


@dataclass(frozen=True)
class PipelineChoice:
    """The pipeline cross-validation chose, and why.

    Attributes
    ----------
    method, friction, gmm : str
        The chosen pipeline.
    candidates : list of tuple
        ``(method, friction, gmm)`` of each candidate scored.
    cv_rms : ndarray, shape (len(candidates), n)
        Cross-validated RMS per joint (N m).
    reason : str
        One sentence a person reads.
    rate_hz : float or None
        The sampling rate the candidates were scored at (None: the recording's own; see
        :data:`RATE_FACTOR`).
    gains : tuple of int
        Joints (0-based) given a drive gain (:func:`choose_gains`; empty: none).
    gain_cv_rms : ndarray, shape (n,), or None
        Cross-validated RMS per joint of the chosen pipeline with those gains (None: no gain kept).
    folds : str
        ``"halves"`` (the recording's two halves), ``"runs"`` (its runs, dealt to two folds) or ``"none"``
        (nothing scored).
    one_motion : bool
        Whether the two folds hold one motion (:func:`one_motion`).
    """

    method: str
    friction: str
    gmm: str | int
    candidates: list[tuple[str, str, str | int]]
    cv_rms: NDArray[np.float64]
    reason: str
    rate_hz: float | None = None
    gains: tuple[int, ...] = ()
    gain_cv_rms: NDArray[np.float64] | None = None
    folds: str = "halves"
    one_motion: bool = False

    @property
    def said(self) -> str:
        """The reason, with the advice :data:`ONE_MOTION` gives when the folds hold one motion."""
        shared = (
            "; the seed friction keeps one static level for both directions (seed_shared): on one motion each "
            "joint reverses at the same configurations in every period, where a level per direction would "
            "also take the model's error there"
            if self.one_motion and self.friction == "seed_shared"
            else ""
        )
        return self.reason + (ONE_MOTION.get(self.folds, "") if self.one_motion else "") + shared

    @property
    def effects(self) -> str | None:
        """The chosen drive gains as an effect list for ``identify(..., effects=)`` (None: no gain)."""
        return ",".join(f"drive_gain@{j + 1}" for j in self.gains) or None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready record (the model file keeps it)."""
        return {
            "method": self.method,
            "friction": self.friction,
            "gmm": self.gmm,
            "candidates": [list(c) for c in self.candidates],
            "cv_rms": np.round(self.cv_rms, 6).tolist(),
            "reason": self.said,
            "rate_hz": None if self.rate_hz is None else float(self.rate_hz),
            "drive_gains": [j + 1 for j in self.gains],
            "drive_gain_cv_rms": None if self.gain_cv_rms is None else np.round(self.gain_cv_rms, 6).tolist(),
            "folds": self.folds,
            "one_motion": self.one_motion,
        }


def candidates(friction: str = "auto", gmm: str | int = "auto") -> list[tuple[str, str, str | int]]:
    """The pipelines scored: the baseline, the baseline with the paper's friction, and the paper's full
    pipeline, with the user's own choices kept.

    The middle one separates the friction model from the rest: on the TX40 the paper's nonlinear friction
    predicts better on every joint while its mixture correction predicts joints 3 and 4 worse (cross-
    validated 0.90 of the baseline's mean relative error, no joint 1 % worse; held out, 0.68-0.92 of
    the baseline's RMS on all six joints, 4 of 6 below FIGAROH's best figures).

    Parameters
    ----------
    friction : str
        "auto" (each candidate its own: linear for the baseline, the paper's ``seed`` for the full
        pipeline) or a friction model every candidate uses.
    gmm : "auto", "off" or int
        The full pipeline's correction ("auto": sized by validation).
    """
    base_friction = "linear" if friction == "auto" else friction
    full_friction = "seed" if friction == "auto" else friction
    out: list[tuple[str, str, str | int]] = [  # from the simplest to the richest
        ("ols", base_friction, "off"),
        ("irls", base_friction, "off"),
        ("ols", full_friction, "off"),
        ("irls", full_friction, gmm),
    ]
    return list(dict.fromkeys(out))


def coarse_recording(data, cutoff: float | None):
    """The recording at a rate of about :data:`RATE_FACTOR` times ``cutoff``, or itself.

    Every signal (angles, torques, measured velocities and accelerations) is low-passed (zero-phase
    Butterworth, order 5, run by run) at 0.8 of the lower rate's Nyquist frequency, then one sample in
    ``D`` is kept (irregular time stamps are first resampled to their median step, as the preprocessing
    would).  Unchanged when ``D`` would be 1 or without a cut-off.

    Parameters
    ----------
    data : Dataset
        The training recording.
    cutoff : float or None
        The torque's cut-off (Hz) the pipelines will use.

    Returns
    -------
    Dataset
    """
    from dynid.data.preprocess import lowpass, resample

    if cutoff is None:
        return data
    fs = 1.0 / data.dt
    D = int(fs / (RATE_FACTOR * cutoff) + 1e-6)  # 999.99... Hz for 1 kHz stamps: still 5 at 20 Hz
    if D < 2:
        return data
    if not data.is_uniform:  # on the uniform grid the preprocessing would resample it to
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its gaps are the preprocessing's to report, once
            data = resample(data)
    runs = data.runs
    keep = np.concatenate([np.arange(r.start, r.stop, D) for r in runs])

    def low(x):
        return None if x is None else lowpass(x, fs=fs, cutoff=0.8 * fs / (2 * D), order=5, runs=runs)[keep]

    sub = data.select_rows(keep)  # the runs' bounds kept
    meta = {**sub.meta, "coarse": {"decimate": D, "rate_hz": fs / D}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return replace(sub, q=low(data.q), tau=low(data.tau), dq=low(data.dq), ddq=low(data.ddq), meta=meta)


def _score(model, ds) -> NDArray[np.float64]:
    prep = model.prepare(ds)
    parts = model.predict_parts(ds, prep=prep)
    pred = parts["link"] + parts["friction"] + parts["gmm"]
    return np.mean((prep.tau_reference - pred) ** 2, axis=0)


def _cross_fit(make, halves, settings, on_done=None):
    """Each of ``settings`` fitted on one fold and scored on the other, both ways.

    Returns the mean squared error (len(settings), n) of the two directions (NaN: a setting a fold could
    not support).
    """
    n = halves[0].n
    total = np.zeros((len(settings), n))
    failed = np.zeros(len(settings), dtype=bool)
    done = 0
    for a, b in ((0, 1), (1, 0)):
        # every setting fitted on one fold, its system built once and let go before the other's
        with sharing_systems():
            for i, setting in enumerate(settings):
                if not failed[i]:
                    try:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            model = make(*setting).fit(halves[a]).model_
                            total[i] += _score(model, halves[b])
                    except DynidError:
                        failed[i] = True  # a setting a fold cannot support (too few samples) is out
                    model = None
                    give_back()  # each fit's freed memory returned before the next one
                done += 1
                if on_done is not None:
                    on_done(done)
    return np.where(failed[:, None], np.nan, total / 2)


_SAID = {"halves": "two halves of the recording", "runs": "the recording's runs, dealt to two folds"}  # by kind


def folds(data) -> tuple[Any, Any, str]:
    """The two folds the candidates are fitted and scored on: ``(fold_a, fold_b, kind)``.

    A recording of several runs (recordings joined with :meth:`~dynid.data.dataset.Dataset.concat`, such
    as two excitations given to ``dynid identify --data A.csv B.csv``, or the pieces of one recording
    between gaps in its stamps) is cut along its runs: whole runs are dealt to two folds, the longest
    first to the fold with fewer samples, when the smaller fold holds at least :data:`RUN_BALANCE` of the
    samples and each fold lasts two seconds (``kind`` ``"runs"``).  A fit on one fold then predicts
    motions it has not seen.  On a simulated xArm 7 with Stribeck friction, two 15 s excitations scored
    the paper's pipeline 14-26 % worse than ordinary least squares on joints 1-3, and IRLS with linear
    friction was chosen (a third excitation held out: every joint within 1.03 times the baseline); the
    two halves of one 30 s excitation had scored the paper's pipeline 31 % better, and it predicted the
    held-out excitation up to 1.37 times worse.  On a UR10 the same runs kept the paper's pipeline (held
    out 0.59-0.70 of the baseline on the large joints).  Otherwise the recording's two contiguous halves
    (``kind`` ``"halves"``).

    Parameters
    ----------
    data : Dataset
        The training recording.

    Returns
    -------
    tuple
        The two folds (datasets) and ``"runs"`` or ``"halves"``.
    """
    runs = data.runs
    if len(runs) > 1:
        sizes = [r.stop - r.start for r in runs]
        dealt: list[list[slice]] = [[], []]
        count = [0, 0]
        for i in sorted(range(len(runs)), key=lambda i: -sizes[i]):
            k = int(count[1] < count[0])
            dealt[k].append(runs[i])
            count[k] += sizes[i]
        if min(count) >= max(RUN_BALANCE * data.m, _MIN_FOLD_ROWS) and all(
            sum(float(data.t[r.stop - 1] - data.t[r.start]) for r in d) >= _MIN_HALF_SECONDS for d in dealt
        ):
            rows = [np.concatenate([np.arange(r.start, r.stop) for r in sorted(d, key=lambda r: r.start)]) for d in dealt]
            return data.select_rows(rows[0]), data.select_rows(rows[1]), "runs"
    half = data.m // 2
    return data.select_rows(np.arange(half)), data.select_rows(np.arange(half, data.m)), "halves"


def _states(data, count: int = 600) -> NDArray[np.float64]:
    """About ``count`` samples of the angles and their speeds, spread over the runs in proportion to their
    length; the speeds are differences over the thinned samples of each run (which smooth the encoder's
    noise, and never cross from one run into the next)."""
    out = []
    for run in data.runs:
        k = max(3, round(count * (run.stop - run.start) / data.m))
        rows = np.unique(np.linspace(run.start, run.stop - 1, min(k, run.stop - run.start)).astype(int))
        if len(rows) < 3:
            continue
        q = data.q[rows]
        out.append(np.hstack([q, np.gradient(q, data.t[rows], axis=0)]))
    return np.vstack(out) if out else np.zeros((0, 2 * data.n))


def one_motion(a, b) -> bool:
    """Whether two folds hold one motion: the median distance from a state ``[q, dq]`` of either to the
    nearest state of the other is below :data:`SAME_MOTION` (both ways), each coordinate centred and in
    its standard deviation over both folds, floored at a twentieth of the largest of its kind (an angle,
    a speed), so that a joint that hardly moves does not count its noise or rounding as motion.  Two
    halves of an excitation played several times, or two recordings of one excitation, are one motion;
    the halves of a recording that moves on, or two excitations, are not.

    Parameters
    ----------
    a, b : Dataset
        The folds.

    Returns
    -------
    bool
    """
    return bool(_motion_distance(a, b) < SAME_MOTION)


def _motion_distance(a, b) -> float:
    """The larger of the two median nearest-state distances of :func:`one_motion` (inf: no states)."""
    A, B = _states(a), _states(b)
    if len(A) == 0 or len(B) == 0:
        return float("inf")
    both = np.vstack([A, B])
    centre, spread = both.mean(axis=0), both.std(axis=0)
    n = a.n
    for kind in (slice(0, n), slice(n, 2 * n)):  # angles, speeds
        spread[kind] = np.maximum(spread[kind], max(0.05 * float(spread[kind].max()), 1e-12))
    A, B = (A - centre) / spread, (B - centre) / spread
    d2 = np.sum(A**2, axis=1)[:, None] + np.sum(B**2, axis=1)[None, :] - 2.0 * A @ B.T  # O(1) values: exact enough
    d = np.sqrt(np.maximum(d2, 0.0))
    return float(max(np.median(d.min(axis=0)), np.median(d.min(axis=1))))


def choose_pipeline(
    make, data, options: list[tuple[str, str, str | int]], *, share_static: bool = False
) -> PipelineChoice:
    """Score candidate pipelines by two-fold blocked cross-validation on the training recording.

    Parameters
    ----------
    make : callable
        ``make(method, friction, gmm) -> ThreeLayerModel`` (unfitted, the user's other settings kept).
    data : Dataset
        The training recording.
    options : list of tuple
        The candidates (:func:`candidates`); the first is the baseline.
    share_static : bool
        When the folds hold one motion (:func:`one_motion`), score and choose the seed friction with one
        static level for both directions (``seed_shared``, :class:`dynid.identify.friction_models.
        SharedSeedFriction`) instead of ``seed`` (the default pipeline's friction was not the user's).

    Returns
    -------
    PipelineChoice
    """
    half = data.m // 2
    if len(options) == 1 or data.duration < 2 * _MIN_HALF_SECONDS or half < _MIN_FOLD_ROWS:
        m, f, g = options[-1]
        return PipelineChoice(
            m, f, g, list(options), np.zeros((len(options), data.n)),
            "the recording is too short to cross-validate two halves of it: the full pipeline is kept",
            folds="none",
        )  # fmt: skip
    a, b, kind = folds(data)
    one = one_motion(a, b)
    if one and share_static:  # one static level for both directions: see SharedSeedFriction
        options = [(m, "seed_shared" if f == "seed" else f, g) for m, f, g in options]
    with stage(f"choosing the pipeline by cross-validation on {_SAID[kind]}", total=2 * len(options)):
        mse = _cross_fit(make, (a, b), options, advance)
    choice = decide(options, np.sqrt(mse), data.meta.get("coarse", {}).get("rate_hz"), kind)
    return replace(choice, one_motion=one)


def gain_screen(system) -> list[int]:
    """Joints (0-based) whose torque a drive gain may explain better by :data:`GAIN_SCREEN`, in-sample.

    A gain on joint ``j`` adds the column ``W_j x`` (the joint's own model torque, ``x`` the ordinary
    least-squares fit) to that joint's rows; it lies in the span of the system's data matrix, so the
    screen needs no other pass over the data.  With each joint's residual scaled to unit RMS, gains are
    added by forward selection while the next one lowers the residual sum of squares by as much as a
    :data:`GAIN_SCREEN` fall of one joint's RMS would; at most ``n - 1`` (a gain on every joint is a
    scale of every parameter).  The link parameters are refitted with each gain, so a gain they can
    take over is not listed; one number on thousands of samples gains little from fitting it in-sample,
    and the refit of :func:`choose_gains` on the folds decides.  Gains on the other joints with every body
    scaled fit exactly alike; where that set is as small (half the joints: on a two-joint arm, always),
    the set whose link parameters keep the description's scale is listed.

    Parameters
    ----------
    system : LinearSystem
        The recording's system with linear friction (:func:`dynid.identify.linear_system.build_system`).

    Returns
    -------
    list of int
        The joints, in the order selected.
    """
    n, m = system.n, system.m
    x = system.solve(np.eye(n)).x
    sigma = np.maximum(system.rms(x), 1e-12)
    stacked = system.stacked(np.diag(1.0 / sigma))  # (n c, p + 1): joint i's block scaled by 1 / sigma_i
    A, b = stacked[:, :-1], stacked[:, -1]
    c = len(system.z_joint)
    reg = np.flatnonzero(system.z_param >= 0)
    G = np.zeros((n * c, n))
    for j in range(n):
        g = np.zeros(c)
        own = reg[system.z_joint[reg] == j]
        g[own] = x[system.z_param[own]] / sigma[j]
        G[j * c : (j + 1) * c, j] = system.R_Z @ g
    Q, _ = np.linalg.qr(A)
    r = b - Q @ (Q.T @ b)
    G_perp = G - Q @ (Q.T @ G)
    scale = np.maximum(np.linalg.norm(G, axis=0), 1e-300)
    need = m * (1.0 - (1.0 - GAIN_SCREEN) ** 2)  # one joint's sum of squares is m after the scaling
    out: list[int] = []
    while len(out) < n - 1:
        norms = np.linalg.norm(G_perp, axis=0)
        free = (norms > 1e-6 * scale) & ~np.isin(np.arange(n), out)
        if not free.any():
            break
        drop = np.where(free, (G_perp.T @ r) ** 2 / np.maximum(norms**2, 1e-300), -np.inf)
        j = int(np.argmax(drop))
        if drop[j] < need:
            break
        out.append(j)
        u = G_perp[:, j] / norms[j]
        r = r - u * (u @ r)
        G_perp = G_perp - np.outer(u, u @ G_perp)
    if out and 2 * len(out) == n:  # the other joints' gains, every body scaled, fit alike: the description decides
        out = _nearer_the_description(system, A, b, G, out)
    return out


def _nearer_the_description(system, A, b, G, joints: list[int]) -> list[int]:
    """Of gains on ``joints`` and on the other joints (the same fit, every body scaled), the set whose link
    parameters keep the scale of the description's (base parameters projected on the description's)."""
    cols = system.columns
    n, nb = system.n, cols.n_base
    phi = np.zeros(cols.P.shape[1])
    phi[: 10 * n] = np.asarray(cols.robot.params, dtype=np.float64)
    x_desc = (cols.P @ phi)[:nb]
    if not np.any(x_desc):
        return joints

    def off_scale(js: list[int]) -> float:
        x = np.linalg.lstsq(np.hstack([A, G[:, js]]), b, rcond=None)[0][:nb]
        s = float(x @ x_desc / (x_desc @ x_desc))
        return abs(np.log(abs(s))) if s != 0 else np.inf

    others = [j for j in range(n) if j not in joints]
    return others if off_scale(others) < off_scale(joints) else joints


def choose_gains(make, data, choice: PipelineChoice, joints: list[int]) -> PipelineChoice:
    """The chosen pipeline with a drive gain on the joints that earn one by cross-validation.

    The joints :func:`gain_screen` lists (``joints``) are refitted with a gain each (``make(method, friction, gmm,
    effects)``, the effect ``drive_gain@j``) on each half and scored on the other.  Gains that lower
    their joint's cross-validated RMS by :data:`GAIN_GAIN` are kept, refitted once more if some were
    dropped, and kept only when no joint ends more than :data:`JOINT_TOLERANCE` worse than without them.
    Nothing is tried when the pipeline was not scored (a recording too short for two halves).  The folds
    are those the pipeline was chosen on (:func:`folds`).

    Parameters
    ----------
    make : callable
        ``make(method, friction, gmm, effects) -> ThreeLayerModel`` (unfitted).
    data : Dataset
        The recording the pipeline was chosen on (the same folds).
    choice : PipelineChoice
        :func:`choose_pipeline`'s choice.
    joints : list of int
        The screened joints (0-based).

    Returns
    -------
    PipelineChoice
        ``choice`` with :attr:`~PipelineChoice.gains` and a sentence added to its reason when a gain is
        kept; else ``choice`` (its reason saying which screened gains did not earn their place).
    """
    joints = list(joints)
    pick = choice.candidates.index((choice.method, choice.friction, choice.gmm))
    before = choice.cv_rms[pick]
    if not joints or not np.all(np.isfinite(before) & (before > 0)):  # nothing screened, or nothing scored
        return choice
    halves = folds(data)[:2]
    setting = (choice.method, choice.friction, choice.gmm)
    n = len(before)
    dropped: list[int] = []
    twin = ""

    def scored(js: list[int]) -> NDArray[np.float64]:
        effects = ",".join(f"drive_gain@{j + 1}" for j in js)
        return np.sqrt(_cross_fit(lambda *s: make(*s, effects), halves, [setting], advance)[0])

    if 2 * len(joints) == n:
        # gains on these joints explain the torques exactly as the inverse gains on the others with every
        # body scaled (a gain on every joint is a scale of every parameter): the screen took the set that
        # keeps the description's scale
        twin = (
            f" (or, alike in the torques, joint(s) {_joints(j for j in range(n) if j not in joints)} with every "
            "body scaled: the description's bodies decided)"
        )
    with stage(f"trying a drive gain on joint(s) {_joints(joints)}", total=2):
        for _ in range(2):
            after = scored(joints)
            if not np.all(np.isfinite(after)):
                return replace(
                    choice,
                    reason=f"{choice.reason}; a drive gain on joint(s) {_joints(joints)} could not be fitted on "
                    "a fold of the recording",
                )
            earned = [j for j in joints if after[j] <= (1 - GAIN_GAIN) * before[j]]  # the screened joints' errors
            if earned == joints:
                if not np.all(after <= (1 + JOINT_TOLERANCE) * before):
                    worse = np.flatnonzero(after > (1 + JOINT_TOLERANCE) * before)
                    return replace(
                        choice,
                        reason=f"{choice.reason}; a drive gain on joint(s) {_joints(joints)} would leave joint(s) "
                        f"{_joints(worse)} more than {100 * JOINT_TOLERANCE:.0f} % worse on the folds",
                    )
                listed = ", ".join(f"{j + 1} ({100 * (1 - after[j] / before[j]):.0f} % lower)" for j in joints)
                also = (
                    f" (screened too, not {100 * GAIN_GAIN:.0f} % lower: joint(s) {_joints(dropped)})" if dropped else ""
                )
                return replace(
                    choice,
                    gains=tuple(joints),
                    gain_cv_rms=after,
                    reason=f"{choice.reason}; a drive gain (measured torque a constant times the model's) on "
                    f"joint(s) {listed} on the folds, no joint {100 * JOINT_TOLERANCE:.0f} % worse{also}{twin}",
                )
            dropped = sorted(set(dropped) | (set(joints) - set(earned)))
            joints = earned
            if not joints or twin:  # a twin pair is kept whole or not at all
                break
    return replace(
        choice,
        reason=f"{choice.reason}; a drive gain on joint(s) {_joints(dropped)} did not lower its cross-validated "
        f"error by {100 * GAIN_GAIN:.0f} %",
    )


def _joints(joints) -> str:
    return ", ".join(str(int(j) + 1) for j in joints)


def decide(
    options: list[tuple[str, str, str | int]],
    cv: NDArray[np.float64],
    rate: float | None = None,
    kind: str = "halves",
) -> PipelineChoice:
    """The choice among scored candidates: the rules of :func:`choose_pipeline`.

    Parameters
    ----------
    options : list of tuple
        The candidates, from the simplest (the baseline) to the richest.
    cv : ndarray, shape (len(options), n)
        Their cross-validated RMS per joint (NaN: a candidate that could not be fitted).
    rate : float, optional
        The rate they were scored at, when the recording was made coarser for it.
    kind : {"halves", "runs"}
        What the two folds were (:func:`folds`), for the reason.

    Returns
    -------
    PipelineChoice
    """
    said = _SAID[kind]
    base = cv[0]
    if not np.all(np.isfinite(base)):
        m, f, g = options[-1]
        return PipelineChoice(m, f, g, list(options), cv, "the baseline could not be fitted on a fold: the full "
                              "pipeline is kept", folds=kind)  # fmt: skip
    fitted = np.all(np.isfinite(cv), axis=1)  # a candidate a fold could not support has no score
    score = np.full(len(options), np.inf)
    score[fitted] = np.mean(cv[fitted] / np.maximum(base, 1e-300), axis=1)
    ok = np.all(cv <= (1 + JOINT_TOLERANCE) * base, axis=1) & np.all(np.isfinite(cv), axis=1)
    ok[0] = True
    best = int(np.argmin(np.where(ok, score, np.inf)))
    # the simplest candidate (the options run from simple to rich) within PARSIMONY of the best
    pick = next(i for i in range(len(options)) if ok[i] and score[i] <= score[best] + PARSIMONY)
    m, f, g = options[pick]
    name = f"{m} + {f} friction + gmm {g}"
    if pick == 0 and best != 0:
        reason = (
            f"{name}: on {said}, each predicting the other, the best richer pipeline "
            f"({'+'.join(map(str, options[best]))}) scores {100 * (1 - score[best]):.0f} % lower, within the "
            f"{100 * PARSIMONY:.0f} points that take the simpler pipeline"
        )
    elif pick == 0:
        worse = []
        for i in range(1, len(options)):
            if not np.all(np.isfinite(cv[i])):
                continue
            far = np.flatnonzero(cv[i] > (1 + JOINT_TOLERANCE) * base)
            label = "+".join(map(str, options[i]))
            worse.append(
                f"{label} is worse on joint(s) {', '.join(str(j + 1) for j in far)}"
                if far.size
                else f"{label} has a mean relative error of {score[i]:.2f}"
            )
        reason = (
            f"{name}: on {said}, each predicting the other, no richer pipeline is better "
            f"in the mean without a joint {100 * JOINT_TOLERANCE:.0f} % worse ({'; '.join(worse) or 'none beats it'})"
        )
    else:
        reason = (
            f"{name}: on {said}, each predicting the other, {100 * (1 - score[pick]):.0f} % "
            f"lower mean relative error than ols + linear friction, and no joint {100 * JOINT_TOLERANCE:.0f} % worse"
        )
    if pick != best and pick != 0:
        reason += (
            f"; {'+'.join(map(str, options[best]))} scores {100 * (score[pick] - score[best]):.0f} points lower, "
            f"within the {100 * PARSIMONY:.0f} points that take the simpler pipeline"
        )
    if rate is not None:
        reason += f" (scored at {rate:.4g} Hz, {RATE_FACTOR:g} times the cut-off or more)"
    return PipelineChoice(m, f, g, list(options), cv, reason, rate, folds=kind)
