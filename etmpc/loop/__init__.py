"""The control loop of the paper's Algorithm 1, generic over the system.

Each step: measure ``x_i``; if there is no plan, or the plan has run out (age = N), or the task put
the plant back in the last step (``task.restarted``: a fallen pole re-erected), or the policy draws
``a_i = 1``, solve a new plan from ``x_i``. Apply the planned input plus the feedback correction
(``-K (x_i - x_hat_i)``, with a fixed LQR gain or one along the plan), clipped to the input bounds.
If a solve fails, the previous plan is kept while it has steps left (the feedback keeps correcting
around it) and the failure is counted; a forced solve that fails is used as it is (the solver's last
iterate). Every recompute attempt counts (``a_i = 1``).

With time in the loop (a task's ``Config.latency`` and ``compute_levels``, :mod:`etmpc.control.timing`)
a solve started at step ``k`` delivers its plan at ``k + d`` while the kept plan runs, the policy is
not asked meanwhile, and a decision may be one SQP iteration instead of a full solve, priced by its
iterations. Latency 0 is the loop above, bit for bit.

A system plugs in by providing what :class:`etmpc.systems.base.System` lists; a policy by providing
what :class:`Policy` lists, deciding from an :class:`AugmentedState` (a :data:`Decision`), and
declaring what else it is, if anything (:class:`Simulates`, :class:`Observes`, :class:`Announces`,
:class:`Clairvoyant`; :func:`simulates` and its siblings read them). Nothing here knows about MuJoCo,
batteries or any particular policy.

This module may import ``etmpc.common``, ``etmpc.control`` and ``etmpc.systems``.

Two ways to play the same loop, bit for bit the same numbers:

* :func:`run_episode` steps the ``dm_env`` interface and keeps everything (a :class:`Trajectory`),
  one :class:`ClosedLoop` step per control interval (``etmpc.envs`` plays the same steps for an agent);
* :func:`play_on` continues from a :class:`Snapshot` of a running episode, stepping the task and
  the physics directly (no ``TimeStep`` per step) and keeping only the return: the fast path the
  rollout policies simulate their futures with.

These are the recording and the light mode of :class:`ClosedLoop` (:mod:`etmpc.loop.modes`), two strategies
it asks, never branches on; the solve in flight (:mod:`etmpc.loop.flight`) and what the controller sees of
the state (:mod:`etmpc.loop.sensed`) are its other collaborators.
"""

from etmpc.loop.closed import ClosedLoop
from etmpc.loop.play import play_on, run_episode
from etmpc.loop.records import Continuation, Trajectory, computation_cost
from etmpc.loop.state import (
    Announces,
    AugmentedState,
    Clairvoyant,
    Decision,
    DecisionContext,
    Observes,
    Policy,
    Simulates,
    Snapshot,
    announcer,
    clairvoyant,
    drawing,
    observes,
    simulates,
)

__all__ = [
    "Announces",
    "AugmentedState",
    "Clairvoyant",
    "ClosedLoop",
    "Continuation",
    "Decision",
    "DecisionContext",
    "Observes",
    "Policy",
    "Simulates",
    "Snapshot",
    "Trajectory",
    "announcer",
    "clairvoyant",
    "computation_cost",
    "drawing",
    "observes",
    "play_on",
    "run_episode",
    "simulates",
]
