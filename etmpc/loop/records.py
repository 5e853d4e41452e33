"""What one episode did (:class:`Trajectory`) and what one continued play did (:class:`Continuation`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from etmpc.control.plan import Plan


def computation_cost(computations, price: float):
    """The price of ``computations`` (a count, a flag, or an array of either, elementwise) at ``price``
    each: the one place etmpc prices a computation. A trigger's reward is the task's minus this."""
    return price * computations


# -- what one episode did --------------------------------------------------------------------------
@dataclass
class Trajectory:
    """Everything one episode did, step by step (arrays preallocated for the full episode)."""

    states: np.ndarray  # (T + 1, nx) measured; rows past `steps` stay NaN
    applied: np.ndarray  # (T, nu) input sent to the plant
    planned: np.ndarray  # (T, nu) the plan's input for that step
    correction: np.ndarray  # (T, nu) LQR correction before clipping
    predicted: np.ndarray  # (T, nx) the plan's prediction x_hat_i
    plan_age: np.ndarray  # (T,) i - k at the decision
    recompute: np.ndarray  # (T,) a_i: a computation was started (includes forced ones)
    forced: np.ndarray  # (T,) the plan had run out (or there was none)
    level: np.ndarray  # (T,) what was computed: 0 keep, 1 one SQP iteration, 2 a full solve (etmpc.control.timing)
    work: np.ndarray  # (T,) the computation's priced work: 1 per solve, or its SQP iterations on a task with levels
    in_flight: np.ndarray  # (T,) a solve was under way at the decision: the trigger was not asked
    rewards: np.ndarray  # (T,) the environment's reward for the step
    # The timings are CPU seconds of the loop's thread (etmpc.loop.closed.cpu_clock), not wall time.
    solve_time_s: np.ndarray  # (T,) CPU time of the MPC computation (NaN where none happened)
    step_time_s: np.ndarray  # (T,) CPU time of the whole step, solve included
    feedback_time_s: np.ndarray  # (T,) CPU time of the input: the plan's, plus the LQR correction, clipped
    decide_time_s: np.ndarray  # (T,) CPU time of the policy's decision (0 where the loop did not ask it)
    plans: list[tuple[int, Plan]] = field(default_factory=list)  # (step made for, plan), successful or used
    arrivals: list[int] = field(default_factory=list)  # the step each of plans came into force (its made step + latency)
    starts: list[int] = field(default_factory=list)  # the step each of plans' computation started (its made step, or earlier)
    steps: int = 0
    solver_failures: int = 0
    nonfinite: bool = False  # the episode ended early on a non-finite state

    @classmethod
    def empty(cls, steps: int, nx: int, nu: int) -> Trajectory:
        nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
        return cls(
            states=nan(steps + 1, nx),
            applied=nan(steps, nu),
            planned=nan(steps, nu),
            correction=nan(steps, nu),
            predicted=nan(steps, nx),
            plan_age=np.zeros(steps, int),
            recompute=np.zeros(steps, bool),
            forced=np.zeros(steps, bool),
            level=np.zeros(steps, np.int8),
            work=np.zeros(steps),
            in_flight=np.zeros(steps, bool),
            rewards=np.zeros(steps),
            solve_time_s=nan(steps),
            step_time_s=nan(steps),
            feedback_time_s=np.zeros(steps),
            decide_time_s=np.zeros(steps),
        )

    def cpu_seconds(self) -> dict[str, float]:
        """The controller's CPU time in this episode, summed over its steps (the loop thread's: a
        machine-dependent figure, which other processes sharing the cores inflate less than wall time, but still
        inflate: compare figures played on an idle machine): the MPC's
        ``solve``s, the ``feedback`` (the LQR), the trigger's ``decide``s (a rollout's simulations included)."""
        n = self.steps
        return {
            "solve": float(np.nansum(self.solve_time_s[:n])),
            "feedback": float(self.feedback_time_s[:n].sum()),
            "decide": float(self.decide_time_s[:n].sum()),
        }

    @property
    def recomputes(self) -> int:
        return int(self.recompute[: self.steps].sum())

    @property
    def total_work(self) -> float:
        """The work priced over the episode: the computations, or their SQP iterations on a task with levels."""
        return float(self.work[: self.steps].sum())

    def policy_rewards(self, recompute_price: float) -> np.ndarray:
        """Per-step rewards the policy maximises: the environment's, minus the price of a computation."""
        return self.rewards[: self.steps] - computation_cost(self.work[: self.steps], recompute_price)

    def policy_return(self, recompute_price: float) -> float:
        """The policy's return: rewards minus the price of every computation."""
        return float(self.rewards[: self.steps].sum() - computation_cost(self.total_work, recompute_price))


@dataclass(eq=False)
class Continuation:
    """What one :func:`play_on` did, step by step, for a caller that picks it up again later (the
    oracle's memo): what each step added to the return, whether it computed, and the controller's
    state after it (``x``, the plan, its age, ``u_prev``). Summed from 0.0 in order, ``added[k:]``
    gives exactly what a play on from the state after step ``k - 1`` returns."""

    start: int  # the step it started at
    added: list[float] = field(default_factory=list)
    recomputed: list[bool] = field(default_factory=list)
    levels: list[int] = field(default_factory=list)  # what each step computed, on a task with compute levels
    after: list[tuple] = field(default_factory=list)

    def return_from(self, k: int) -> float:
        """The return from its ``k``-th step on, summed as :func:`play_on` sums it."""
        total = 0.0
        for added in self.added[k:]:
            total += added
        return total
