"""The IPOPT problem of one excitation try: decision vector, constraints on the grid, smooth criterion.

The trajectory on the optimisation grid and its limits are an SX graph (linear in the decision vector);
the base regressor is mapped over the grid inside an MX graph, ``A = H*^T H*`` formed with one dense
product, and the criterion is a CasADi callback on ``A`` (:mod:`dynid.optim.criteria`).  One
:class:`ExcitationNlp` per problem graph and thread (:func:`excitation_nlp`), its solvers built once.
"""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np

from dynid.optim.criteria import CriterionCallback, SmoothCriterion
from dynid.optim.interrupts import StopCallback, solving
from dynid.optim.problem import ExcitationFunctions, ExcitationProblem

__all__ = ["ExcitationNlp", "excitation_nlp"]

_IPOPT_OPTIONS = {
    "hessian_approximation": "limited-memory",
    "limited_memory_max_history": 10,
    # The limited-memory update as extra rows and columns of the KKT system, one factorisation, instead
    # of Sherman-Morrison back-solves: the same iterates (the criterion equal to 1e-3 after 40
    # iterations on 6 UR5 starts) for 13 ms of CPU per iteration instead of 23.  (A history of 20
    # costs 15 ms per iteration with it; of 5, no less than 10.)
    "limited_memory_aug_solver": "extended",
    "jac_d_constant": "yes",
    "tol": 1e-6,
    # Many random starts matter more than polishing each: stop once the objective has changed by
    # less than 1e-4 (relative) over 5 iterations at a dual infeasibility below 1e-3.  Measured on
    # the Panda (cond, 6 starts): half the iterations (108 instead of 216 on average) for an exact
    # cond 2 % higher per try.
    "acceptable_tol": 1e-3,
    "acceptable_obj_change_tol": 1e-4,
    "acceptable_iter": 5,
    "max_iter": 300,
    "print_level": 0,
    "sb": "yes",
    # The adaptive barrier update spends a third of the time in extra back-solves (1080+ constraints,
    # limited-memory Hessian); monotone reached the same exact cond with 10 % less CPU on UR5.
    "mu_strategy": "monotone",
}


_WARM_OPTIONS = {
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_slack_bound_push": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
    "mu_init": 1e-4,
}


class ExcitationNlp:
    """IPOPT on the decision vector y for one problem; built once per process and reused.

    ``multipliers`` holds the constraint and bound multipliers of the last solve (a warm start's).
    """

    def __init__(self, problem: ExcitationProblem, functions: ExcitationFunctions) -> None:
        n, m, k = problem.n, problem.grid, problem.harmonics - 1
        nb = functions.n_base
        self.problem = problem
        self.nb = nb
        pa, pb = problem.null_bases
        sq, cq, c_, s_, ds, dc = problem.basis(problem.times())
        # The trajectory on the grid and the constraints, in SX (small, their Jacobian is generated
        # as SX too: with Cartesian limits an MX Jacobian made each IPOPT iteration twice as slow).
        ys = ca.SX.sym("y", problem.n_free)
        ya = ca.reshape(ys[: k * n], k, n)
        yb = ca.reshape(ys[k * n : 2 * k * n], k, n)
        offset = ys[2 * k * n :]
        Qs = ca.repmat(offset.T, m, 1) + ca.mtimes(ca.DM(sq @ pa), ya) - ca.mtimes(ca.DM(cq @ pb), yb)
        DQs = ca.mtimes(ca.DM(c_ @ pa), ya) + ca.mtimes(ca.DM(s_ @ pb), yb)
        DDQs = -ca.mtimes(ca.DM(ds @ pa), ya) + ca.mtimes(ca.DM(dc @ pb), yb)
        gs = [ca.vec(Qs), ca.vec(DQs), ca.vec(DDQs)]
        self.cart_axes: np.ndarray = np.zeros(0, dtype=int)
        cart = problem.cartesian
        if cart is not None and cart.active:
            lo, hi = cart.bounds()
            self.cart_axes = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
            P = functions.fk.map(m)(Qs.T)[0]  # 3 x m
            gs.append(ca.vec(P[self.cart_axes.tolist(), :].T))
        states = ca.Function("grid_states", [ys], [Qs.T, DQs.T, DDQs.T])
        constraints = ca.Function("constraints", [ys], [ca.vertcat(*gs)])
        y = ca.MX.sym("y", problem.n_free)
        QT, DQT, DDQT = states(y)
        # Base regressor over the grid: n x (m n_b), samples side by side; regrouped as H*^T (n_b x m n)
        # with the columns ordered joint by joint, then scaled by 1 / sigma_joint.
        R = functions.base_regressor.map(m)(QT, DQT, DDQT)
        Ht = ca.reshape(R.T, nb, m * n)
        row_weight = np.repeat(1.0 / np.asarray(problem.noise_std), m)
        Ht = Ht * ca.repmat(ca.DM(row_weight).T, nb, 1)
        A = ca.mtimes(Ht, Ht.T)
        par = ca.MX.sym("p", nb * nb + 3 + nb)
        prior = ca.reshape(par[: nb * nb], nb, nb)
        w = par[nb * nb : nb * nb + 3]
        scale = par[nb * nb + 3 :]
        self.criterion = CriterionCallback(
            "excitation_criterion",
            SmoothCriterion(problem.criterion, functions.gravity_related, problem.sharpness),
            nb,
        )
        f = self.criterion(A + prior, w, scale)
        self.A = ca.Function("information", [y], [A], ["y"], ["A"])
        options = dict(_IPOPT_OPTIONS)
        if self.cart_axes.size:
            options["jac_d_constant"] = "no"
        g = constraints(y)
        nlp = {"x": y, "p": par, "f": f, "g": g}
        # stops IPOPT at its next iteration once a signal came (CasADi swallows the KeyboardInterrupt)
        self.stop = StopCallback("excitation_stop", problem.n_free, g.shape[0], par.shape[0])
        common = {"print_time": False, "error_on_fail": False, "iteration_callback": self.stop}
        self.solver = ca.nlpsol("excitation", "ipopt", nlp, {"ipopt": options, **common})
        # Re-solves after tightening start from the previous solution and multipliers, with a small
        # barrier parameter: the solution moves little.
        self.warm_solver = ca.nlpsol(
            "excitation_warm",
            "ipopt",
            nlp,
            {"ipopt": dict(options, **_WARM_OPTIONS), **common},
        )
        self._nlp_dict, self._options, self._common = nlp, options, common
        self._screen_solvers: dict[int, ca.Function] = {}
        self.multipliers: tuple[np.ndarray, np.ndarray] | None = None

    def screen_solver(self, max_iter: int) -> ca.Function:
        """A solver that stops after ``max_iter`` iterations (a screening solve), built once per size."""
        solver = self._screen_solvers.get(max_iter)
        if solver is None:
            options = dict(self._options, max_iter=int(max_iter))
            solver = self._screen_solvers[max_iter] = ca.nlpsol(
                f"excitation_screen_{max_iter}", "ipopt", self._nlp_dict, {"ipopt": options, **self._common}
            )
        return solver

    def bounds(self, margins: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """lbg, ubg for the limits reduced by ``margins`` (same keys as the violations)."""
        robot, m = self.problem.robot, self.problem.grid
        q_lo = robot.q_min + margins["q_low"]
        q_hi = robot.q_max - margins["q_high"]
        dq = robot.dq_max - margins["dq"]
        ddq = robot.ddq_max - margins["ddq"]
        lbg = [np.repeat(q_lo, m), np.repeat(-dq, m), np.repeat(-ddq, m)]
        ubg = [np.repeat(q_hi, m), np.repeat(dq, m), np.repeat(ddq, m)]
        if self.cart_axes.size:
            lo, hi = self.problem.cartesian.bounds()
            lo = lo + margins["cart_low"]
            hi = hi - margins["cart_high"]
            lbg.append(np.repeat(lo[self.cart_axes], m))
            ubg.append(np.repeat(hi[self.cart_axes], m))
        return np.concatenate(lbg), np.concatenate(ubg)

    def solve(
        self,
        y0: np.ndarray,
        par: np.ndarray,
        margins: dict[str, np.ndarray],
        *,
        warm: bool = False,
        max_iter: int | None = None,
        multipliers: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, str, int]:
        """Solve from ``y0``; ``warm`` re-uses the multipliers of the previous solve (or ``multipliers``);
        ``max_iter`` screens."""
        if warm and multipliers is not None:
            self.multipliers = multipliers
        lbg, ubg = self.bounds(margins)
        with solving():
            if max_iter is not None:
                solver = self.screen_solver(max_iter)
                sol = solver(x0=y0, p=par, lbg=lbg, ubg=ubg)
            elif warm and self.multipliers is not None and _WARM_OPTIONS:
                solver = self.warm_solver
                sol = solver(
                    x0=y0, p=par, lbg=lbg, ubg=ubg, lam_g0=self.multipliers[0], lam_x0=self.multipliers[1]
                )
            else:
                solver = self.solver
                sol = solver(x0=y0, p=par, lbg=lbg, ubg=ubg)
        self.multipliers = (np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["lam_x"]).ravel())
        stats = solver.stats()
        return np.asarray(sol["x"]).ravel(), str(stats.get("return_status", "?")), int(stats.get("iter_count", -1))


_NLPS: dict[tuple, ExcitationNlp] = {}
_NLPS_LOCK = threading.Lock()


def _graph_key(problem: ExcitationProblem) -> tuple:
    cart = problem.cartesian
    axes = () if cart is None or not cart.active else tuple(np.isfinite(np.concatenate(cart.bounds())))
    return (
        problem.robot.key,
        problem.n,
        problem.harmonics,
        problem.base_freq,
        problem.grid,
        problem.criterion,
        problem.sharpness,
        np.asarray(problem.noise_std).tobytes(),
        axes,
    )


def excitation_nlp(problem: ExcitationProblem, functions: ExcitationFunctions) -> ExcitationNlp:
    """The IPOPT problem of ``problem``'s graph for the calling thread, built on first use."""
    # One per thread too: a solver keeps the multipliers of its last solve (threading backend, or a
    # Dask worker's threads).  The cache is shared by those threads: its reads and writes hold a lock,
    # and it keeps a few graphs per live thread, so that no thread rebuilds its solvers for every try.
    key = (*_graph_key(problem), threading.get_ident())
    with _NLPS_LOCK:
        nlp = _NLPS.get(key)
    if nlp is None:
        nlp = ExcitationNlp(problem, functions)  # built outside the lock: threads build theirs at once
        with _NLPS_LOCK:
            while len(_NLPS) >= max(4, 2 * threading.active_count()):
                _NLPS.pop(next(iter(_NLPS)))
            _NLPS[key] = nlp
    else:
        nlp.problem = problem  # same graph; the limits (bounds) may differ
    return nlp
