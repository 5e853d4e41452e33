"""Nonlinear least-squares MPC solved by a Gauss-Newton SQP (CasADi ``sqpmethod`` + ``qrqp``).

The OCP

    min  sum_{k<N} |r(x_k, u_k, u_k - u_{k-1})|^2 + |r_N(x_N)|^2
    s.t. x_0 = x_measured,  x_{k+1} = F(x_k, u_k),  u_min <= u_k <= u_max

is transcribed by multiple shooting with the variables in stage order ``[x0 u0 x1 u1 .. xN]``
(the order structure-exploiting QP solvers need) and handed to ``sqpmethod`` with a Gauss-Newton
Hessian ``2 J_r^T J_r``: always positive semi-definite, so every QP is convex, and exact at the
optimum for the KKT conditions (only the path to it differs from an exact-Hessian SQP). Warm
started from the previous plan this takes 2-3 QPs. ``tests/test_mpc.py`` checks its optimum
against a tightly converged Ipopt on random states.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from etmpc.plan import Plan


@dataclass(frozen=True)
class SolverSettings:
    tolerance: float = 1e-8  # sqpmethod tol_pr and tol_du
    max_iterations: int = 100
    qpsol: str = "qrqp"
    qpsol_options: tuple[tuple[str, object], ...] = ()
    jit: bool = False  # compile the NLP's functions with the system's C compiler


class GaussNewtonMPC:
    def __init__(
        self,
        model: ca.Function,
        stage_residual: ca.Function,
        terminal_residual: ca.Function,
        horizon: int,
        u_min: np.ndarray,
        u_max: np.ndarray,
        settings: SolverSettings = SolverSettings(),
    ):
        """``model(x, u) -> x+``; ``stage_residual(x, u, du) -> r``; ``terminal_residual(x) -> r``."""
        nx, nu = model.size1_in(0), model.size1_in(1)
        self.nx, self.nu, self.horizon = nx, nu, horizon
        self.u_min, self.u_max = np.atleast_1d(u_min).astype(float), np.atleast_1d(u_max).astype(float)

        # Variables, stage ordered.
        xs = [ca.SX.sym(f"x{k}", nx) for k in range(horizon + 1)]
        us = [ca.SX.sym(f"u{k}", nu) for k in range(horizon)]
        w = ca.vertcat(*[v for k in range(horizon) for v in (xs[k], us[k])], xs[horizon])
        x_measured, u_prev = ca.SX.sym("x_measured", nx), ca.SX.sym("u_prev", nu)
        params = ca.vertcat(x_measured, u_prev)

        # Objective as a residual vector.
        residuals, previous = [], u_prev
        for k in range(horizon):
            residuals.append(stage_residual(xs[k], us[k], us[k] - previous))
            previous = us[k]
        residuals.append(terminal_residual(xs[horizon]))
        r = ca.vertcat(*residuals)

        # Dynamics: initial condition, then one gap-closing constraint per stage.
        g = ca.vertcat(xs[0] - x_measured, *[model(xs[k], us[k]) - xs[k + 1] for k in range(horizon)])

        # Gauss-Newton Hessian of the Lagrangian.
        lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
        jac_r = ca.jacobian(r, w)
        hess = ca.Function(
            "gauss_newton_hessian",
            [w, params, lam_f, lam_g],
            [lam_f * 2 * (jac_r.T @ jac_r)],
            ["x", "p", "lam_f", "lam_g"],
            ["hess_gamma_x_x"],
        )
        quiet = {"error_on_fail": False}
        if settings.qpsol == "qrqp":
            quiet |= {"print_iter": False, "print_header": False, "print_info": False}
        self._solver = ca.nlpsol(
            "mpc",
            "sqpmethod",
            {"x": w, "p": params, "f": ca.sumsqr(r), "g": g},
            {
                "qpsol": settings.qpsol,
                "qpsol_options": quiet | dict(settings.qpsol_options),
                **({"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O2"]}} if settings.jit else {}),
                "hess_lag": hess,
                "tol_pr": settings.tolerance,
                "tol_du": settings.tolerance,
                "max_iter": settings.max_iterations,
                "print_time": False,
                "print_header": False,
                "print_iteration": False,
                "print_status": False,
                "error_on_fail": False,
            },
        )
        stage_lb = np.concatenate([np.full(nx, -np.inf), self.u_min])
        stage_ub = np.concatenate([np.full(nx, np.inf), self.u_max])
        self._lbw = np.concatenate([np.tile(stage_lb, horizon), np.full(nx, -np.inf)])
        self._ubw = np.concatenate([np.tile(stage_ub, horizon), np.full(nx, np.inf)])
        self._model = model
        self.nlp = {"x": w, "p": params, "f": ca.sumsqr(r), "g": g}  # for reference solvers and tests

    # -- packing ----------------------------------------------------------------------------------
    def pack(self, inputs: np.ndarray, states: np.ndarray) -> np.ndarray:
        n, nu = self.horizon, self.nu
        stages = np.concatenate([states[:n], inputs.reshape(n, nu)], axis=1).ravel()
        return np.concatenate([stages, states[n]])

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, nx, nu = self.horizon, self.nx, self.nu
        stages = w[: n * (nx + nu)].reshape(n, nx + nu)
        states = np.vstack([stages[:, :nx], w[n * (nx + nu) :]])
        return stages[:, nx:].copy(), states

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._lbw, self._ubw

    def rollout(self, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        states = [np.asarray(x0, dtype=float)]
        for u in inputs:
            states.append(np.asarray(self._model(states[-1], u)).ravel())
        return np.array(states)

    # -- solving ----------------------------------------------------------------------------------
    def initial_guess(self, x: np.ndarray, warm: Plan | None, age: int) -> np.ndarray:
        """The previous plan shifted by its age, or zero inputs rolled out from ``x``."""
        if warm is None:
            inputs = np.zeros((self.horizon, self.nu))
            states = self.rollout(x, inputs)
        else:
            inputs, states = warm.shifted(age)
            states = states.copy()
            states[0] = x
        return self.pack(inputs, states)

    def solve(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None = None, age: int = 0) -> Plan:
        """Plan from the measured state ``x``; the first input change is against ``u_prev``.

        Warm started from ``warm`` shifted by ``age``; if that fails, retried once from a cold
        start (zero inputs), since a poor warm start is the usual cause of a failed SQP.
        """
        p = np.concatenate([x, np.atleast_1d(u_prev)])
        start = time.perf_counter()
        plan = self._solve_from(self.initial_guess(x, warm, age), p, x)
        if not plan.success and warm is not None:
            retry = self._solve_from(self.initial_guess(x, None, 0), p, x)
            if retry.success:
                plan = retry
        return replace(plan, solve_time_s=time.perf_counter() - start)

    def _solve_from(self, w0: np.ndarray, p: np.ndarray, x: np.ndarray) -> Plan:
        sol = self._solver(x0=w0, p=p, lbx=self._lbw, ubx=self._ubw, lbg=0.0, ubg=0.0)
        w = np.asarray(sol["x"]).ravel()
        cost = float(sol["f"])
        try:  # stats() can raise when the QP solver failed inside the SQP
            stats = self._solver.stats()
            success, iterations, status = bool(stats["success"]), int(stats["iter_count"]), str(stats["return_status"])
        except RuntimeError as exc:
            success, iterations, status = False, -1, f"stats unavailable: {exc}"
        if not (np.all(np.isfinite(w)) and np.isfinite(cost)):
            success, status = False, "non-finite iterate"
            w, cost = self.initial_guess(x, None, 0), float("nan")
        inputs, states = self.unpack(w)
        return Plan(inputs, states, cost, 0.0, success, iterations, status)
