"""The sqpmethod route's NLP (:mod:`etmpc.control.sqpmethod`): the OCP (:class:`~etmpc.control.ocp.OCP`)
transcribed by multiple shooting with shooting nodes every ``block`` intervals (partial condensing).

The variables are every input and the states at steps ``block, 2 block, .., N``, in stage order, and
within a block the states are the predictor's rollout from the block's node. With ``block = 1`` this
is plain multiple shooting, with ``block = N`` single shooting; every choice is the same NLP (the
eliminated states are functions of the variables), so the optimum is the same. A few nodes keep
multiple shooting's fast Gauss-Newton convergence from a warm start (2 QPs) while the QP's KKT system,
which ``qrqp`` factorises at every active-set change, shrinks several times.

Besides the NLP: its Gauss-Newton Hessian ``2 J_r^T J_r`` (plus ``regularisation I``), the KKT
residuals at a point, and the planned trajectory (the states at every step) of a point.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from etmpc.control.ocp import OCP


@dataclass(frozen=True, eq=False)
class ShootingNLP:
    """The NLP ``{"x": w, "p": p, "f": f, "g": g}`` (``p``: the measured state, the previous input, the
    OCP's parameters), its Gauss-Newton Hessian ``hessian(w, p, lam_f, lam_g)``, ``kkt(w, p, lam_x, lam_g)``
    (constraint violation, the Lagrangian's gradient), ``trajectory(w, p)`` (the states ``x_0..x_N``), the
    bounds on ``w``, and where the inputs ``(N, nu)`` and the node states ``(nodes, nx)`` sit in ``w``."""

    nlp: dict[str, ca.SX]
    hessian: ca.Function
    kkt: ca.Function
    trajectory: ca.Function
    lower: np.ndarray
    upper: np.ndarray
    u_index: np.ndarray
    x_index: np.ndarray
    node_steps: np.ndarray

    def pack(self, inputs: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Variables from a plan's inputs ``(N, nu)`` and states ``(N + 1, nx)`` (nodes only used)."""
        w = np.empty(self.lower.shape[0])
        w[self.u_index] = inputs
        w[self.x_index] = states[self.node_steps]
        return w


def transcribe(ocp: OCP, block: int, regularisation: float) -> ShootingNLP:
    """The NLP of ``ocp`` with shooting nodes every ``block`` intervals, its Hessian regularised by
    ``regularisation I``."""
    nx, nu, horizon, parameters = ocp.nx, ocp.nu, ocp.horizon, ocp.parameters
    nodes = [k for k in range(block, horizon, block)] + [horizon]

    # Variables in stage order: [u0 .. x_node u_node .. x_N]; x0, u_prev (and the parameters) are parameters.
    x_measured, u_prev = ca.SX.sym("x_measured", nx), ca.SX.sym("u_prev", nu)
    extra = ca.SX.sym("parameters", parameters)
    params = ca.vertcat(x_measured, u_prev, extra) if parameters else ca.vertcat(x_measured, u_prev)
    node_states = {k: ca.SX.sym(f"x{k}", nx) for k in nodes}
    us = [ca.SX.sym(f"u{k}", nu) for k in range(horizon)]
    order: list[ca.SX] = []
    u_positions: list[int] = []
    node_index: dict[int, int] = {}
    for k in range(horizon):
        if k in node_states:
            node_index[k] = sum(v.shape[0] for v in order)
            order.append(node_states[k])
        u_positions.append(sum(v.shape[0] for v in order))
        order.append(us[k])
    node_index[horizon] = sum(v.shape[0] for v in order)
    order.append(node_states[horizon])
    w = ca.vertcat(*order)
    u_index = np.array(u_positions)[:, None] + np.arange(nu)  # (N, nu) positions in w
    x_index = np.array([node_index[k] for k in nodes])[:, None] + np.arange(nx)

    # Residuals, gaps at the nodes, and the predicted trajectory (nodes from the variables).
    residuals: list[ca.SX] = []
    gaps: list[ca.SX] = []
    states: list[ca.SX] = []
    x, previous = x_measured, u_prev
    for k in range(horizon):
        if k in node_states:
            x = node_states[k]
        states.append(x)
        residuals.append(ocp.stage_residual(*ocp.with_parameters(extra, x, us[k], us[k] - previous)))
        previous = us[k]
        x = ocp.model(x, us[k])
        if k + 1 in node_states:
            gaps.append(x - node_states[k + 1])
    states.append(node_states[horizon])
    residuals.append(ocp.terminal_residual(*ocp.with_parameters(extra, node_states[horizon])))
    r = ca.vertcat(*residuals)
    g = ca.vertcat(*gaps)
    f = ca.sumsqr(r)

    # Gauss-Newton Hessian of the Lagrangian.
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
    jac_r = ca.jacobian(r, w)
    gauss_newton = lam_f * 2 * (jac_r.T @ jac_r)
    if regularisation:
        gauss_newton = gauss_newton + regularisation * ca.SX.eye(w.shape[0])
    hessian = ca.Function(
        "gauss_newton_hessian", [w, params, lam_f, lam_g], [gauss_newton], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"]
    )
    nw = w.shape[0]
    lower, upper = np.full(nw, -np.inf), np.full(nw, np.inf)
    lower[u_index], upper[u_index] = ocp.u_min, ocp.u_max

    # KKT residuals at a point: constraint violation and the Lagrangian's gradient.
    lam_x = ca.SX.sym("lam_x", nw)
    violation = ca.mmax(ca.vertcat(ca.fabs(g), ca.fmax(lower - w, 0), ca.fmax(w - upper, 0)))
    grad_lagrangian = ca.gradient(f, w) + ca.jtimes(g, w, lam_g, True) + lam_x
    kkt = ca.Function("kkt", [w, params, lam_x, lam_g], [ca.vertcat(violation, ca.norm_inf(grad_lagrangian))])
    trajectory = ca.Function("trajectory", [w, params], [ca.vertcat(*states)])
    return ShootingNLP(
        nlp={"x": w, "p": params, "f": f, "g": g},
        hessian=hessian,
        kkt=kkt,
        trajectory=trajectory,
        lower=lower,
        upper=upper,
        u_index=u_index,
        x_index=x_index,
        node_steps=np.array(nodes),
    )
