"""The condensed route of the Gauss-Newton MPC: its own SQP on the inputs alone, each QP a dense one
solved by DAQP (``SolverSettings(route="condensed")``).

**The OCP**, :class:`~etmpc.control.mpc.GaussNewtonMPC`'s, made stage-separable by carrying the
previous input in the state, ``z_k = (x_k, u_{k-1})``, so that the input-rate residual is local to a
stage:

    z_{k+1} = (F(x_k, u_k), u_k),   min  sum_{k<N} |r(x_k, u_k, u_k - z_k[nx:])|^2 + |r_N(x_N)|^2
    s.t. u_min <= u_k <= u_max,     z_0 = (x_measured, u_previous).

**Condensed, single shooting.** The variables are the ``N nu`` inputs ``U``; the states are their
rollout through the predictor from the measured state. So every iterate is a plan the predictor
would fly, converged or not, and a QP has bounds only: always feasible.

**An iteration** (Gauss-Newton, as :mod:`etmpc.control.mpc`'s):

1. *Linearise* (one generated C function): along the rollout, each stage's Jacobians, then the
   condensed Gauss-Newton Hessian ``H = 2 J'J + mu I`` and gradient ``g = 2 J'r`` of the objective in
   ``U`` by a backward recursion over the stages, never forming the rollout's Jacobian ``J``:
   ``P_k = Q_k + A_k'P_{k+1}A_k``, ``lambda_k = q_k + A_k'lambda_{k+1}`` give the diagonal blocks
   ``H_kk = R_k + B_k'P_{k+1}B_k``, ``g_k = s_k + B_k'lambda_{k+1}`` and
   ``M_i = S_i + B_i'P_{i+1}A_i``, and the blocks below them are ``H_ij = M_i A_{i-1} .. A_{j+1} B_j``
   (``Q, S, R, q, s``: the stage's ``C'C, D'C, D'D, C'r, D'r`` with ``C, D`` the residual's Jacobians
   in ``z`` and ``u``). ``O(N^2)`` small products, each written out for the model's sparsity.
2. *The QP* ``min 1/2 d'Hd + g'd`` s.t. ``u_min - U <= d <= u_max - U``, by DAQP (a dual
   active-set method for dense QPs, in C); if DAQP cannot solve it (a Hessian too ill-conditioned to
   factorise), again with Levenberg-Marquardt damping on its diagonal.
3. *Converged?* The QP's step is zero exactly at a KKT point of the OCP: when it moves no input by
   more than ``step_tolerance`` of its range, the iterate is returned (the step is not taken).
4. *A step* ``U + t d``, ``t`` halved from 1 until the objective falls by Armijo's rule.

**Warm start**: the previous plan shifted by its age and flown from the measured state by the predictor
under the plan's own feedback gains (``u = u_j - K_j (x - x_j)``, clipped: what keeping it would do),
padded past its end with its last input, state and gain. Replaying the old inputs open loop from a
state they were not planned for diverges within the horizon on an unstable plant (a quadrotor tips
over in the prediction), and the linearisation along such a rollout is useless (its Gauss-Newton
Hessian reaches 1e19, beyond any QP solver). With no plan (a cold start), the same flight holds the
measured state and the previous input under the LQR of the predictor linearised there. Without
feedback weights the guess is the old inputs shifted, or the previous input held.

All arithmetic that decides a plan runs in the generated C and in DAQP's C, or elementwise in NumPy:
no BLAS kernel, so no machine's choice of one, touches a plan's bits.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import casadi as ca
import daqp
import numpy as np

from etmpc.control.compiled import CompiledFunction, CompileError, compile_functions, run
from etmpc.control.plan import Plan
from etmpc.control.riccati import gains_along

ARMIJO = 1e-4  # sufficient decrease: f(U + t d) <= f(U) + ARMIJO t g'd
SMALLEST_STEP = 2.0**-20  # the line search gives up below this fraction of the QP's step
# Shares of H's largest diagonal entry added to its diagonal, in turn, when DAQP cannot solve the QP.
DAMPING = (1e-8, 1e-4, 1.0)


@dataclass(frozen=True)
class Outcome:
    """One run of the SQP: its inputs ``(N, nu)``, their rollout ``(N + 1, nx)``, the objective, the
    gains along the plan (or None), the QPs solved, and how it ended."""

    inputs: np.ndarray
    states: np.ndarray
    cost: float
    gains: np.ndarray | None
    iterations: int
    converged: bool
    status: str
    usable: bool  # finite and every QP solved: a plan the loop may apply


def _sx_function(name: str, sparsities, body) -> ca.Function:
    """An SX function of symbols with the given sparsities: ``body(*symbols) -> outputs``."""
    symbols = [ca.SX.sym(f"a{i}", sparsity) for i, sparsity in enumerate(sparsities)]
    return ca.Function(name, symbols, body(*symbols))


class CondensedGaussNewton:
    """The SQP of the module's docstring for the OCP of ``ocp``, a
    :class:`~etmpc.control.mpc.GaussNewtonMPC`: its predictor ``model(x, u) -> x+``, its residuals, horizon,
    input bounds, ``parameters`` (the OCP's other parameters, given last to both residuals), its
    ``SolverSettings`` and its feedback weights, as it was given them; ``name`` names the compiled code."""

    def __init__(self, ocp, name: str):
        model, N, settings = ocp._model, ocp.horizon, ocp.settings
        nx, nu = model.size1_in(0), model.size1_in(1)
        self.nx, self.nu, self.horizon, self.settings, self.feedback = nx, nu, N, settings, ocp.feedback
        self._lower, self._upper = np.tile(ocp.u_min, N), np.tile(ocp.u_max, N)
        span = self._upper - self._lower
        bounded = np.isfinite(span) & (span > 0)
        self._step_scale = np.where(bounded, 1.0 / np.where(bounded, span, 1.0), 1.0)  # per input: 1 / its range (1: unbounded)
        self._no_constraints = np.zeros((0, N * nu))
        functions = self._functions(model, ocp.stage_residual, ocp.terminal_residual, ocp.parameters, name)
        self._compiled = self._linearisers = None
        if settings.compiled:
            try:
                compiled = compile_functions(list(functions.values()))
                self._compiled = dict(zip(functions, compiled, strict=True))
                # Two of the linearisation, whose buffers take turns: a trial step's linearisation does not
                # overwrite the iterate's, and neither is copied out.
                first = self._compiled["linearise"]
                second = CompiledFunction(functions["linearise"], bundle=list(functions.values()), library=first.library)
                self._linearisers = (first, second)
            except CompileError as exc:
                warnings.warn(
                    f"{exc}; the MPC runs in CasADi's virtual machine instead (slower, same plans)", RuntimeWarning, stacklevel=4
                )
        self._interpreted = functions

    @property
    def is_compiled(self) -> bool:
        return self._compiled is not None

    # -- the functions, generated once --------------------------------------------------------------
    def _functions(self, model, stage_residual, terminal_residual, parameters: int, name: str) -> dict[str, ca.Function]:
        nx, nu, N = self.nx, self.nu, self.horizon
        nz = nx + nu
        z, u, p = ca.SX.sym("z", nz), ca.SX.sym("u", nu), ca.SX.sym("p", parameters)
        extra = (p,) if parameters else ()
        x, previous = z[:nx], z[nx:]
        z_next = ca.vertcat(model(x, u), u)
        r = stage_residual(x, u, u - previous, *extra)
        r_N = terminal_residual(x, *extra)
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

        U, z0, P = ca.MX.sym("U", N * nu), ca.MX.sym("z0", nz), ca.MX.sym("p", parameters)
        inputs = [U[k * nu : (k + 1) * nu] for k in range(N)]
        z_k, f, Z, stages = z0, 0, [z0], []
        for k in range(N):
            z_k, f_k, *rest = stage(z_k, inputs[k], P)
            stages.append(rest)
            f, Z = f + f_k, Z + [z_k]
        f_N, P_k, lam = terminal(z_k, P)
        f = f + f_N
        P_k, lam = ca.densify(P_k), ca.densify(lam)
        M, diagonal, g = [None] * N, [None] * N, [None] * N
        for k in range(N - 1, -1, -1):
            P_k, lam, M[k], diagonal[k], g[k] = back(P_k, lam, *stages[k][:7])
        blocks = [[None] * N for _ in range(N)]
        for i in range(N):
            blocks[i][i] = diagonal[i]
            T = ca.densify(M[i])
            for j in range(i - 1, -1, -1):
                blocks[i][j], T = below(T, stages[j][0], stages[j][1])
                blocks[j][i] = blocks[i][j].T
        H = 2 * ca.blockcat(blocks) + self.settings.regularisation * ca.MX.eye(N * nu)
        A_x = ca.horzcat(*[ca.densify(s[7]) for s in stages])  # (nx, N nx): the predictor's linearisation
        B_x = ca.horzcat(*[ca.densify(s[8]) for s in stages])
        states = ca.horzcat(*[z[:nx] for z in Z])
        functions = {
            "linearise": ca.Function(
                f"{name}_linearise",
                [U, z0, P],
                [f, ca.densify(2 * ca.vertcat(*g)), ca.densify(H), states, A_x, B_x],
                ["U", "z0", "p"],
                ["f", "g", "H", "states", "A", "B"],
            )
        }
        z_k, f = z0, 0
        for k in range(N):
            z_k, f_k = stage_cost(z_k, inputs[k], P)
            f = f + f_k
        functions["objective"] = ca.Function(
            f"{name}_objective", [U, z0, P], [f + terminal_cost(z_k, P)], ["U", "z0", "p"], ["f"]
        )
        if self.feedback is not None:
            A_all, B_all = ca.MX.sym("A", nx, N * nx), ca.MX.sym("B", nx, N * nu)
            gains = gains_along(
                lambda k: (A_all[:, k * nx : (k + 1) * nx], B_all[:, k * nu : (k + 1) * nu]), N, self.feedback, nx, nu
            )
            functions["gains"] = ca.Function(f"{name}_gains", [A_all, B_all], [gains], ["A", "B"], ["K"])
            # the warm start: a kept plan flown by the predictor under its own gains, clipped
            x_0, planned = ca.SX.sym("x", nx), ca.SX.sym("inputs", nu, N)
            predicted, gain = ca.SX.sym("states", nx, N), ca.SX.sym("gains", nu * nx, N)
            lower, upper = ca.DM(self._lower[:nu]), ca.DM(self._upper[:nu])
            x_k, flown = x_0, []
            for k in range(N):
                K_k = ca.reshape(gain[:, k], nx, nu).T
                u_k = ca.fmin(ca.fmax(planned[:, k] - K_k @ (x_k - predicted[:, k]), lower), upper)
                flown.append(u_k)
                x_k = model(x_k, u_k)
            functions["flown"] = flown = ca.Function(
                f"{name}_flown", [x_0, planned, predicted, gain], [ca.vertcat(*flown)], ["x", "inputs", "states", "gains"], ["U"]
            )
            # the cold start: hold the state and the input, under the LQR of the predictor linearised there
            x_c, u_c = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
            A_c, B_c = stage(ca.vertcat(x_c, u_c), u_c, P)[9:11]
            held = gains_along(lambda k: (A_c, B_c), N, self.feedback, nx, nu)
            U_c = flown(x_c, ca.repmat(u_c, 1, N), ca.repmat(x_c, 1, N), ca.reshape(held, nu * nx, N))
            functions["cold"] = ca.Function(f"{name}_cold", [x_c, u_c, P], [U_c], ["x", "u", "p"], ["U"])
        return functions

    def _call(self, name: str, *args) -> list[np.ndarray]:
        """Function ``name`` at ``args``: its output buffers (the compiled ones are overwritten by its next call)."""
        return run(self._interpreted[name], None if self._compiled is None else self._compiled[name], *args)

    def plan(self, x, u_prev, warm: Plan | None, age: int, parameters, limit: int, rollout) -> Plan:
        """A plan from at most ``limit`` iterations from :meth:`guess`. Every iterate is a descent from the
        guess and a plan the predictor flies, so one that stops short of the tolerance is still a plan
        (``success``; ``status`` says it did not converge); a plan fails only when a linearisation is not
        finite or the first QP is not solved, from the warm guess and then from a cold one (its states are
        then ``rollout(x, inputs)``)."""
        start = time.perf_counter()
        use_warm = warm is not None and (age < self.horizon or self.settings.warm_from_expired)
        extra = np.zeros(0) if parameters is None else np.asarray(parameters, dtype=float)
        out = self.run(x, u_prev, self.guess(x, u_prev, warm, age, extra, use_warm), extra, limit)
        if not out.usable and use_warm:  # a warm start flown into a useless linearisation: once more, cold
            out = self.run(x, u_prev, self.guess(x, u_prev, None, 0, extra), extra, limit)
        inputs, states, cost, gains = out.inputs, out.states, out.cost, out.gains
        if not out.usable:
            states, cost = rollout(x, inputs), float("nan")
            gains = None if self.feedback is None else np.zeros((self.horizon, self.nu, self.nx))
        return Plan(inputs, states, cost, time.perf_counter() - start, out.usable, out.iterations, out.status, gains=gains)

    # -- a guess --------------------------------------------------------------------------------------
    def guess(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray, use_warm: bool = True
    ) -> np.ndarray:
        """The first iterate ``U`` (the module's docstring): the kept plan flown under its gains, shifted
        without them; with no plan, the state held under the LQR there, or ``u_prev`` held; within the bounds."""
        N = self.horizon
        if (warm is None or not use_warm) and self.feedback is not None:
            U = self._call("cold", x, u_prev, parameters)[0].copy()
        elif warm is None or not use_warm:
            U = np.tile(np.asarray(u_prev, dtype=float), N)
        else:
            idx_u = np.minimum(np.arange(N) + age, N - 1)
            if self.feedback is not None and warm.gains is not None:
                idx_x = np.minimum(np.arange(N) + age, N)
                states, gains = warm.states[idx_x], warm.gains[idx_u]
                U = self._call("flown", x, warm.inputs[idx_u].ravel(), states.ravel(), gains.ravel())[0].copy()
            else:
                U = warm.inputs[idx_u].ravel().astype(float)
        return np.minimum(np.maximum(U, self._lower), self._upper)

    # -- the SQP --------------------------------------------------------------------------------------
    def run(self, x: np.ndarray, u_prev: np.ndarray, U: np.ndarray, parameters: np.ndarray, limit: int) -> Outcome:
        """At most ``limit`` QPs from ``U`` (within the bounds), stopping when converged."""
        tolerance = self.settings.step_tolerance
        z0 = np.concatenate([np.asarray(x, dtype=float), np.atleast_1d(np.asarray(u_prev, dtype=float))])
        p = np.asarray(parameters, dtype=float)
        slot = 0  # the buffer of the iterate's linearisation; a trial's goes to the other
        f, g, H, states, A, B = self._linearised(U, z0, p, slot)
        iterations, converged, usable, status = 0, False, True, ""
        while iterations < limit:
            if not (math.isfinite(f) and np.isfinite(g).all() and np.isfinite(H).all()):
                usable, status = False, "non-finite linearisation"
                break
            d, flag = self._step(H, g, U)
            iterations += 1
            if flag < 1 or not np.isfinite(d).all():
                usable, status = iterations > 1, f"QP failed (DAQP exit flag {flag})"
                break
            if np.max(np.abs(d) * self._step_scale) <= tolerance:
                converged, status = True, "converged"
                break
            slope, t = math.fsum(g * d), 1.0
            while True:
                trial = np.minimum(np.maximum(U + t * d, self._lower), self._upper)  # rounding may leave the box by an ulp
                if t == 1.0:
                    f_trial, *rest = self._linearised(trial, z0, p, 1 - slot)
                else:
                    f_trial = float(self._call("objective", trial, z0, p)[0][0])
                if f_trial <= f + ARMIJO * t * slope:
                    break
                t *= 0.5
                if t < SMALLEST_STEP:
                    trial = None
                    break
            if trial is None:
                status = f"line search found no decrease along the QP's step ({iterations} iterations)"
                break
            U, slot = trial, 1 - slot
            if t == 1.0:
                f, g, H, states, A, B = f_trial, *rest
            else:
                f, g, H, states, A, B = self._linearised(U, z0, p, slot)
        else:
            status = f"not converged in {limit} iteration(s)"
        inputs, states = U.reshape(self.horizon, self.nu).copy(), states.reshape(self.horizon + 1, self.nx).copy()
        gains = None
        if self.feedback is not None and usable:
            gains = self._call("gains", A, B)[0].reshape(self.horizon, self.nu, self.nx).copy()
        usable = (
            usable and math.isfinite(f) and bool(np.isfinite(states).all()) and (gains is None or bool(np.isfinite(gains).all()))
        )
        return Outcome(inputs, states, float(f), gains, iterations, converged, status, usable)

    def _step(self, H: np.ndarray, g: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, int]:
        """The QP's step and DAQP's exit flag (1: solved). A QP DAQP cannot solve is one whose Hessian is too
        ill-conditioned to factorise (a prediction from a tumbling or upturned drone reaches 1e19): it is
        solved again with Levenberg-Marquardt damping, ``H + share max(diag H) I`` for each share of
        :data:`DAMPING` until one is solved: a shorter step along a descent direction."""
        d, _, flag, _ = daqp.solve(H, g, self._no_constraints, self._upper - U, self._lower - U)
        for share in DAMPING:
            if flag >= 1 or not np.isfinite(H).all():
                break
            damped = H + (share * float(np.max(np.diag(H)))) * np.eye(H.shape[0])
            d, _, flag, _ = daqp.solve(damped, g, self._no_constraints, self._upper - U, self._lower - U)
        return d, flag

    def _linearised(self, U: np.ndarray, z0: np.ndarray, p: np.ndarray, slot: int):
        """``(f, g, H, states, A, B)`` at ``U``: compiled, the arrays are buffer ``slot``'s (0 or 1), valid
        until that buffer's next linearisation."""
        n = U.shape[0]
        if self._linearisers is None:
            f, g, H, states, A, B = self._call("linearise", U, z0, p)
        else:
            (f, g, H, states, A, B), code = self._linearisers[slot].call(U, z0, p)
            if code != 0:
                raise FloatingPointError(f"the linearisation failed (code {code})")
        return float(f[0]), g, H.reshape(n, n), states, A, B
