"""How an MPC's OCP is solved: :class:`SolverSettings`, read by :class:`~etmpc.control.mpc.GaussNewtonMPC`
and its condensed route (:mod:`etmpc.control.condensed`)."""

from __future__ import annotations

from dataclasses import dataclass

ROUTES = ("sqpmethod", "condensed")


@dataclass(frozen=True)
class SolverSettings:
    """How an MPC's OCP is solved. ``route``: ``"sqpmethod"`` (CasADi's SQP on the multiple-shooting NLP, its
    QPs by ``qpsol``: reads ``tolerance``, ``dual_tolerance``, ``qpsol``, ``qpsol_options``, ``block``,
    ``sqp_options``, ``cold_start``) or ``"condensed"`` (:mod:`etmpc.control.condensed`: a Gauss-Newton SQP
    on the inputs alone, its dense QPs by DAQP; reads ``step_tolerance``). Both read ``max_iterations``,
    ``regularisation``, ``compiled`` and ``warm_from_expired``."""

    tolerance: float = 1e-8  # sqpmethod tol_pr (and tol_du unless dual_tolerance is given)
    max_iterations: int = 100
    qpsol: str = "qrqp"
    qpsol_options: tuple[tuple[str, object], ...] = ()
    block: int = 4  # shooting nodes every `block` intervals (1: full multiple shooting)
    compiled: bool = True  # generated C, built once per machine; False: CasADi's virtual machine
    dual_tolerance: float | None = None  # sqpmethod tol_du (None: tolerance)
    regularisation: float = 0.0  # mu I added to the Gauss-Newton Hessian (Levenberg-Marquardt); 0: none
    sqp_options: tuple[tuple[str, object], ...] = ()  # more sqpmethod options (merit_memory, max_iter_ls, ...)
    # A cold start's guess: "rollout" (zero inputs, the predictor's states from x) or "hold" (zero
    # inputs, every state x). Near an unstable equilibrium "hold" stays near it, where a rollout of
    # zero inputs falls away and can lead the SQP to another optimum (a pole swung over the top).
    cold_start: str = "rollout"
    warm_from_expired: bool = True  # False: a plan kept to its end (or past a restart) gives no warm start
    route: str = "sqpmethod"
    # The condensed route has converged when the QP's step moves no input by more than this share of its range.
    step_tolerance: float = 1e-3
