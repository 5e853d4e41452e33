"""The condensed route of the Gauss-Newton MPC: its own SQP on the inputs alone, each QP a dense one
solved by DAQP (``SolverSettings(route="condensed")``): a route of :mod:`etmpc.control.route`.

**The OCP** (:class:`~etmpc.control.ocp.OCP`), made stage-separable by carrying the
previous input in the state, ``z_k = (x_k, u_{k-1})``, so that the input-rate residual is local to a
stage:

    z_{k+1} = (F(x_k, u_k), u_k),   min  sum_{k<N} |r(x_k, u_k, u_k - z_k[nx:])|^2 + |r_N(x_N)|^2
    s.t. u_min <= u_k <= u_max,     z_0 = (x_measured, u_previous).

**Condensed, single shooting.** The variables are the ``N nu`` inputs ``U``; the states are their
rollout through the predictor from the measured state. So every iterate is a plan the predictor
would fly, converged or not, and a QP has bounds only: always feasible.

**An iteration** (Gauss-Newton, as :mod:`etmpc.control.sqpmethod`'s):

1. *Linearise* (one generated C function, :mod:`etmpc.control.condensing`): along the rollout, the
   condensed Gauss-Newton Hessian ``H = 2 J'J + mu I`` and gradient ``g = 2 J'r`` of the objective in
   ``U``, by a backward recursion over the stages that never forms the rollout's Jacobian ``J``.
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
from typing import NamedTuple

import daqp
import numpy as np

from etmpc.control.compiled import CompiledFunction, CompileError, compile_functions, run
from etmpc.control.condensing import condensed_functions
from etmpc.control.ocp import OCP
from etmpc.control.plan import Plan
from etmpc.control.riccati import FeedbackWeights
from etmpc.control.settings import SolverSettings

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


class Linearisation(NamedTuple):
    """The linearisation at an iterate: the objective, its gradient and Gauss-Newton Hessian in ``U``, the
    rollout's states and the predictor's Jacobians along it (``linearise`` of :mod:`etmpc.control.condensing`)."""

    f: float
    g: np.ndarray
    H: np.ndarray
    states: np.ndarray
    A: np.ndarray
    B: np.ndarray


class CondensedGaussNewton:
    """The route of the module's docstring for ``ocp`` under ``settings`` (it reads ``max_iterations``,
    ``step_tolerance``, ``regularisation``, ``compiled`` and ``warm_from_expired``), with, given
    ``feedback``, the gains of a TV-LQR along each plan; ``name`` names the compiled code."""

    def __init__(self, ocp: OCP, settings: SolverSettings, feedback: FeedbackWeights | None, name: str):
        N = ocp.horizon
        self.ocp, self.settings, self.feedback = ocp, settings, feedback
        self._lower, self._upper = np.tile(ocp.u_min, N), np.tile(ocp.u_max, N)
        span = self._upper - self._lower
        bounded = np.isfinite(span) & (span > 0)
        self._step_scale = np.where(bounded, 1.0 / np.where(bounded, span, 1.0), 1.0)  # per input: 1 / its range (1: unbounded)
        self._no_constraints = np.zeros((0, N * ocp.nu))
        functions = condensed_functions(ocp, settings.regularisation, feedback, name)
        self._compiled: dict[str, CompiledFunction] | None = None
        self._linearisers: tuple[CompiledFunction, CompiledFunction] | None = None
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

    def prepare_iterations(self) -> None:
        """Nothing to make: an iteration runs the functions a solve runs."""

    def solve(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None) -> Plan:
        """A plan from at most ``max_iterations`` iterations (:meth:`iterate`)."""
        return self.iterate(x, u_prev, warm, age, parameters, self.settings.max_iterations)

    def _call(self, name: str, *args: np.ndarray) -> list[np.ndarray]:
        """Function ``name`` at ``args``: its output buffers (the compiled ones are overwritten by its next call)."""
        return run(self._interpreted[name], None if self._compiled is None else self._compiled[name], *args)

    def iterate(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None, limit: int
    ) -> Plan:
        """A plan from at most ``limit`` iterations from :meth:`warm_start`. Every iterate is a descent from the
        guess and a plan the predictor flies, so one that stops short of the tolerance is still a plan
        (``success``; ``status`` says it did not converge); a plan fails only when a linearisation is not
        finite or the first QP is not solved, from the warm guess and then from a cold one (its states are
        then the predictor's rollout of its inputs)."""
        start = time.perf_counter()
        use_warm = warm is not None and (age < self.ocp.horizon or self.settings.warm_from_expired)
        extra = np.zeros(0) if parameters is None else np.asarray(parameters, dtype=float)
        out = self.run(x, u_prev, self.warm_start(x, u_prev, warm if use_warm else None, age, extra), extra, limit)
        if not out.usable and use_warm:  # a warm start flown into a useless linearisation: once more, cold
            out = self.run(x, u_prev, self.warm_start(x, u_prev, None, 0, extra), extra, limit)
        inputs, states, cost, gains = out.inputs, out.states, out.cost, out.gains
        if not out.usable:
            states, cost = self.ocp.rollout(x, inputs), float("nan")
            gains = None if self.feedback is None else np.zeros((self.ocp.horizon, self.ocp.nu, self.ocp.nx))
        return Plan(inputs, states, cost, time.perf_counter() - start, out.usable, out.iterations, out.status, gains=gains)

    # -- a guess --------------------------------------------------------------------------------------
    def warm_start(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None = None
    ) -> np.ndarray:
        """The first iterate ``U`` (the module's docstring): the kept plan flown under its gains, shifted
        without them; with no plan, the state held under the LQR there, or ``u_prev`` held; within the bounds."""
        N = self.ocp.horizon
        if warm is None and self.feedback is not None:
            extra = np.zeros(0) if parameters is None else np.asarray(parameters, dtype=float)
            U = self._call("cold", x, u_prev, extra)[0].copy()
        elif warm is None:
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
            accepted: np.ndarray | None = None
            while t >= SMALLEST_STEP:
                trial = np.minimum(np.maximum(U + t * d, self._lower), self._upper)  # rounding may leave the box by an ulp
                if t == 1.0:
                    at_trial = self._linearised(trial, z0, p, 1 - slot)
                    f_trial = at_trial.f
                else:
                    f_trial = float(self._call("objective", trial, z0, p)[0][0])
                if f_trial <= f + ARMIJO * t * slope:
                    accepted = trial
                    break
                t *= 0.5
            if accepted is None:
                status = f"line search found no decrease along the QP's step ({iterations} iterations)"
                break
            U, slot = accepted, 1 - slot
            if t == 1.0:
                f, g, H, states, A, B = at_trial
            else:
                f, g, H, states, A, B = self._linearised(U, z0, p, slot)
        else:
            status = f"not converged in {limit} iteration(s)"
        horizon, nu, nx = self.ocp.horizon, self.ocp.nu, self.ocp.nx
        inputs, states = U.reshape(horizon, nu).copy(), states.reshape(horizon + 1, nx).copy()
        gains = None
        if self.feedback is not None and usable:
            gains = self._call("gains", A, B)[0].reshape(horizon, nu, nx).copy()
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

    def _linearised(self, U: np.ndarray, z0: np.ndarray, p: np.ndarray, slot: int) -> Linearisation:
        """``(f, g, H, states, A, B)`` at ``U``: compiled, the arrays are buffer ``slot``'s (0 or 1), valid
        until that buffer's next linearisation."""
        n = U.shape[0]
        if self._linearisers is None:
            f, g, H, states, A, B = self._call("linearise", U, z0, p)
        else:
            (f, g, H, states, A, B), code = self._linearisers[slot].call(U, z0, p)
            if code != 0:
                raise FloatingPointError(f"the linearisation failed (code {code})")
        return Linearisation(float(f[0]), g, H.reshape(n, n), states, A, B)
