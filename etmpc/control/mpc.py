"""Nonlinear least-squares MPC solved by a Gauss-Newton SQP, by the route its settings name
(``SolverSettings.route``, :mod:`etmpc.control.route`).

The OCP (:class:`~etmpc.control.ocp.OCP`, a value built once from the system)

    min  sum_{k<N} |r(x_k, u_k, u_k - u_{k-1})|^2 + |r_N(x_N)|^2
    s.t. x_0 = x_measured,  x_{k+1} = F(x_k, u_k),  u_min <= u_k <= u_max

is solved by one of the routes:

* ``"sqpmethod"`` (:mod:`etmpc.control.sqpmethod`): CasADi's ``sqpmethod`` with ``qrqp`` on the NLP of
  multiple shooting with a node every ``block`` intervals (:mod:`etmpc.control.shooting`), the solve one
  compiled C function;
* ``"condensed"`` (:mod:`etmpc.control.condensed`): a Gauss-Newton SQP on the inputs alone, each QP a dense
  one with bounds only, solved by DAQP.

Both use the Gauss-Newton Hessian ``2 J_r^T J_r`` (always positive semi-definite, so every QP is convex),
warm start from the previous plan shifted by its age and retry a failed warm solve once from a cold guess.
The MPC picks its route once, when it is made; a solve, a counted iteration, a warm start and whether the
route is compiled are the route's (:class:`~etmpc.control.route.Route`).
"""

from __future__ import annotations

import numpy as np
import casadi as ca

from etmpc.control.ocp import OCP
from etmpc.control.plan import Plan
from etmpc.control.riccati import FeedbackWeights
from etmpc.control.route import ROUTE_CLASSES, Route
from etmpc.control.settings import ROUTES, SolverSettings, check_block

__all__ = ["FeedbackWeights", "GaussNewtonMPC", "ROUTES", "SolverSettings"]


class GaussNewtonMPC:
    """The MPC of the module's docstring: its :attr:`ocp` and its :attr:`route`, picked once."""

    def __init__(
        self,
        model: ca.Function,
        stage_residual: ca.Function,
        terminal_residual: ca.Function,
        horizon: int,
        u_min: np.ndarray,
        u_max: np.ndarray,
        settings: SolverSettings = SolverSettings(),
        name: str = "mpc",
        parameters: int = 0,
        feedback: FeedbackWeights | None = None,
    ):
        """``model(x, u) -> x+``; ``stage_residual(x, u, du) -> r``; ``terminal_residual(x) -> r``.

        With ``parameters > 0`` the OCP has that many more parameters (a reference, say), given to
        :meth:`solve` and passed to both residuals last: ``stage_residual(x, u, du, p)``,
        ``terminal_residual(x, p)``. With ``feedback``, every plan carries the gains of a
        time-varying LQR along it (:class:`FeedbackWeights`). ``name`` names the compiled code."""
        check_block(settings.block, horizon)  # the rest of the settings was checked when they were made
        self.settings, self.feedback = settings, feedback
        self.ocp = OCP(
            model,
            stage_residual,
            terminal_residual,
            horizon,
            np.atleast_1d(u_min).astype(float),
            np.atleast_1d(u_max).astype(float),
            parameters,
        )
        self.route: Route = ROUTE_CLASSES[settings.route](self.ocp, settings, feedback, name)

    @property
    def is_compiled(self) -> bool:
        """Whether the route runs as compiled C (it falls back to CasADi's virtual machine without a compiler)."""
        return self.route.is_compiled

    def objective(self, x: np.ndarray, u_prev: np.ndarray, inputs: np.ndarray, parameters: np.ndarray | None = None) -> float:
        """The OCP's objective of an input sequence ``(N, nu)``, rolled out through the predictor
        from ``x`` (single shooting: no variable but the inputs)."""
        return self.ocp.objective(x, u_prev, inputs, parameters)

    def rollout(self, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """The predictor's states ``(len(inputs) + 1, nx)`` from ``x0`` under ``inputs``."""
        return self.ocp.rollout(x0, inputs)

    def solve(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None = None, age: int = 0, parameters: np.ndarray | None = None
    ) -> Plan:
        """Plan from the measured state ``x``; the first input change is against ``u_prev``;
        ``parameters``: the OCP's other parameters (as many as the constructor was told).

        Warm started from ``warm`` shifted by ``age``; if that fails, retried once from a cold
        start, since a poor warm start is the usual cause of a failed SQP.
        """
        return self.route.solve(x, u_prev, warm, age, parameters)

    def iterate(
        self,
        x: np.ndarray,
        u_prev: np.ndarray,
        warm: Plan | None = None,
        age: int = 0,
        parameters: np.ndarray | None = None,
        limit: int = 1,
    ) -> Plan:
        """Plan by SQP iterations counted one by one: at most ``limit`` of them from ``warm`` shifted by
        ``age`` (a cold guess without one), stopping as soon as the route's convergence test passes.
        ``Plan.iterations`` says how many were made: the work a solve did, which a price per
        iteration and a latency per iteration read.

        ``limit=1`` is one real-time iteration (Diehl's RTI, here with the route's line search): the
        plan is then usable if it is finite (``success``) though not converged (``status`` says so).
        With ``limit=settings.max_iterations`` it is a full solve, retried once from a cold guess when a
        warm start fails. On ``sqpmethod`` each iteration is one call of a compiled one-iteration SQP
        whose multipliers start from zero (which the Gauss-Newton Hessian does not depend on): the same
        optimum as :meth:`solve`, within its tolerance, not the same bits; on ``condensed`` a full
        :meth:`iterate` is :meth:`solve`."""
        if limit < 1:
            raise ValueError(f"limit must be at least 1 iteration, got {limit}")
        return self.route.iterate(x, u_prev, warm, age, parameters, limit)

    def prepare_iterations(self) -> None:
        """Make (and build, or load from the cache) what :meth:`iterate` calls, which is otherwise made when
        first asked for: a system whose every solve is counted in iterations makes it with its MPC, so
        that no solve's measured time holds a one-off build."""
        self.route.prepare_iterations()
