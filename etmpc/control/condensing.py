"""The condensed route's functions (:mod:`etmpc.control.condensed`), generated once per OCP and run as C.

On the OCP made stage-separable by carrying the previous input in the state, ``z_k = (x_k, u_{k-1})``:

* ``linearise(U, z0, p)``: along the rollout of the inputs ``U`` from ``z0``, each stage's Jacobians,
  then the condensed Gauss-Newton Hessian ``H = 2 J'J + mu I`` and gradient ``g = 2 J'r`` of the objective
  in ``U`` by a backward recursion over the stages, never forming the rollout's Jacobian ``J``:
  ``P_k = Q_k + A_k'P_{k+1}A_k``, ``lambda_k = q_k + A_k'lambda_{k+1}`` give the diagonal blocks
  ``H_kk = R_k + B_k'P_{k+1}B_k``, ``g_k = s_k + B_k'lambda_{k+1}`` and
  ``M_i = S_i + B_i'P_{i+1}A_i``, and the blocks below them are ``H_ij = M_i A_{i-1} .. A_{j+1} B_j``
  (``Q, S, R, q, s``: the stage's ``C'C, D'C, D'D, C'r, D'r`` with ``C, D`` the residual's Jacobians
  in ``z`` and ``u``). ``O(N^2)`` small products, each written out for the model's sparsity. Also the
  rollout's states and the predictor's linearisation at each step (for the gains);
* ``objective(U, z0, p)``: the objective alone (the line search's trial steps);
* with feedback weights, ``gains(A, B)`` (the TV-LQR along a plan), ``flown(x, inputs, states, gains)``
  (a kept plan flown by the predictor under its own gains, clipped: the warm start) and ``cold(x, u, p)``
  (the state and the input held, under the LQR of the predictor linearised there: the cold start).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as ca

from etmpc.control.ocp import OCP
from etmpc.control.riccati import FeedbackWeights, gains_along


def _sx_function(name: str, sparsities: Sequence[ca.Sparsity], body: Callable[..., list[ca.SX]]) -> ca.Function:
    """An SX function of symbols with the given sparsities: ``body(*symbols) -> outputs``."""
    symbols = [ca.SX.sym(f"a{i}", sparsity) for i, sparsity in enumerate(sparsities)]
    return ca.Function(name, symbols, body(*symbols))


def condensed_functions(ocp: OCP, regularisation: float, feedback: FeedbackWeights | None, name: str) -> dict[str, ca.Function]:
    """The functions of the module's docstring for ``ocp``, ``mu = regularisation``; ``name`` prefixes theirs."""
    nx, nu, N = ocp.nx, ocp.nu, ocp.horizon
    nz = nx + nu
    z, u, p = ca.SX.sym("z", nz), ca.SX.sym("u", nu), ca.SX.sym("p", ocp.parameters)
    extra = (p,) if ocp.parameters else ()
    x, previous = z[:nx], z[nx:]
    z_next = ca.vertcat(ocp.model(x, u), u)
    r = ocp.stage_residual(x, u, u - previous, *extra)
    r_N = ocp.terminal_residual(x, *extra)
    A, B = ca.jacobian(z_next, z), ca.jacobian(z_next, u)
    C, D, C_N = ca.jacobian(r, z), ca.jacobian(r, u), ca.jacobian(r_N, z)
    stage = ca.Function(
        "stage", [z, u, p], [z_next, ca.sumsqr(r), A, B, C.T @ C, D.T @ C, D.T @ D, C.T @ r, D.T @ r, A[:nx, :nx], B[:nx, :]]
    )
    stage_cost = ca.Function("stage_cost", [z, u, p], [z_next, ca.sumsqr(r)])
    terminal = ca.Function("terminal", [z, p], [ca.sumsqr(r_N), C_N.T @ C_N, C_N.T @ r_N])
    terminal_cost = ca.Function("terminal_cost", [z, p], [ca.sumsqr(r_N)])
    dense = ca.Sparsity.dense
    sparsity = [stage.sparsity_out(i) for i in range(stage.n_out())]
    # one stage back: (P, lambda, A, B, Q, S, R, q, s) -> (P_k, lambda_k, M_k, H_kk, g_k)
    back = _sx_function(
        "back",
        [dense(nz, nz), dense(nz, 1), *sparsity[2:9]],
        lambda P, lam, A_, B_, Q, S, R, q, s: [
            Q + A_.T @ P @ A_,
            q + A_.T @ lam,
            S + B_.T @ P @ A_,
            R + B_.T @ P @ B_,
            s + B_.T @ lam,
        ],
    )
    # one block further below the diagonal: (T, A_j, B_j) -> (T B_j, T A_j)
    below = _sx_function("below", [dense(nu, nz), sparsity[2], sparsity[3]], lambda T, A_, B_: [T @ B_, T @ A_])

    U, z0, P = ca.MX.sym("U", N * nu), ca.MX.sym("z0", nz), ca.MX.sym("p", ocp.parameters)
    inputs = [U[k * nu : (k + 1) * nu] for k in range(N)]
    functions = {"linearise": _linearise(N, nu, regularisation, stage, terminal, back, below, U, z0, P, inputs, name)}
    z_k: ca.MX = z0
    f: ca.MX | int = 0
    for k in range(N):
        z_k, f_k = stage_cost(z_k, inputs[k], P)
        f = f + f_k
    functions["objective"] = ca.Function(f"{name}_objective", [U, z0, P], [f + terminal_cost(z_k, P)], ["U", "z0", "p"], ["f"])
    if feedback is not None:
        functions |= _starts(ocp, feedback, stage, P, name)
    return functions


def _linearise(
    N: int,
    nu: int,
    regularisation: float,
    stage: ca.Function,
    terminal: ca.Function,
    back: ca.Function,
    below: ca.Function,
    U: ca.MX,
    z0: ca.MX,
    P: ca.MX,
    inputs: list[ca.MX],
    name: str,
) -> ca.Function:
    """``linearise(U, z0, p) -> (f, g, H, states, A, B)``: the rollout, then the backward recursion."""
    nx = z0.shape[0] - nu
    z_k: ca.MX = z0
    f: ca.MX | int = 0
    Z = [z0]
    stages: list[list[ca.MX]] = []
    for k in range(N):
        z_k, f_k, *rest = stage(z_k, inputs[k], P)
        stages.append(rest)
        f = f + f_k
        Z = Z + [z_k]
    f_N, P_k, lam = terminal(z_k, P)
    f = f + f_N
    P_k, lam = ca.densify(P_k), ca.densify(lam)
    M: list[ca.MX] = [ca.MX()] * N  # each filled below, from the last stage back
    diagonal: list[ca.MX] = [ca.MX()] * N
    g: list[ca.MX] = [ca.MX()] * N
    for k in range(N - 1, -1, -1):
        P_k, lam, M[k], diagonal[k], g[k] = back(P_k, lam, *stages[k][:7])
    blocks: list[list[ca.MX]] = [[ca.MX()] * N for _ in range(N)]  # every block filled below
    for i in range(N):
        blocks[i][i] = diagonal[i]
        T = ca.densify(M[i])
        for j in range(i - 1, -1, -1):
            blocks[i][j], T = below(T, stages[j][0], stages[j][1])
            blocks[j][i] = blocks[i][j].T
    H = 2 * ca.blockcat(blocks) + regularisation * ca.MX.eye(N * nu)
    A_x = ca.horzcat(*[ca.densify(s[7]) for s in stages])  # (nx, N nx): the predictor's linearisation
    B_x = ca.horzcat(*[ca.densify(s[8]) for s in stages])
    states = ca.horzcat(*[z[:nx] for z in Z])
    return ca.Function(
        f"{name}_linearise",
        [U, z0, P],
        [f, ca.densify(2 * ca.vertcat(*g)), ca.densify(H), states, A_x, B_x],
        ["U", "z0", "p"],
        ["f", "g", "H", "states", "A", "B"],
    )


def _starts(ocp: OCP, feedback: FeedbackWeights, stage: ca.Function, P: ca.MX, name: str) -> dict[str, ca.Function]:
    """``gains``, ``flown`` (the warm start) and ``cold`` (the cold start) of the module's docstring."""
    nx, nu, N = ocp.nx, ocp.nu, ocp.horizon
    A_all, B_all = ca.MX.sym("A", nx, N * nx), ca.MX.sym("B", nx, N * nu)
    gains = gains_along(lambda k: (A_all[:, k * nx : (k + 1) * nx], B_all[:, k * nu : (k + 1) * nu]), N, feedback, nx, nu)
    functions = {"gains": ca.Function(f"{name}_gains", [A_all, B_all], [gains], ["A", "B"], ["K"])}
    # the warm start: a kept plan flown by the predictor under its own gains, clipped
    x_0, planned = ca.SX.sym("x", nx), ca.SX.sym("inputs", nu, N)
    predicted, gain = ca.SX.sym("states", nx, N), ca.SX.sym("gains", nu * nx, N)
    lower, upper = ca.DM(ocp.u_min), ca.DM(ocp.u_max)
    x_k: ca.SX = x_0
    flown_inputs = []
    for k in range(N):
        K_k = ca.reshape(gain[:, k], nx, nu).T
        u_k = ca.fmin(ca.fmax(planned[:, k] - K_k @ (x_k - predicted[:, k]), lower), upper)
        flown_inputs.append(u_k)
        x_k = ocp.model(x_k, u_k)
    functions["flown"] = flown = ca.Function(
        f"{name}_flown", [x_0, planned, predicted, gain], [ca.vertcat(*flown_inputs)], ["x", "inputs", "states", "gains"], ["U"]
    )
    # the cold start: hold the state and the input, under the LQR of the predictor linearised there
    x_c, u_c = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
    A_c, B_c = stage(ca.vertcat(x_c, u_c), u_c, P)[9:11]
    held = gains_along(lambda k: (A_c, B_c), N, feedback, nx, nu)
    U_c = flown(x_c, ca.repmat(u_c, 1, N), ca.repmat(x_c, 1, N), ca.reshape(held, nu * nx, N))
    functions["cold"] = ca.Function(f"{name}_cold", [x_c, u_c, P], [U_c], ["x", "u", "p"], ["U"])
    return functions
