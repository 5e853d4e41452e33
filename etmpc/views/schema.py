"""What a Rerun recording of episodes holds: where each episode lives in the file and what series it has
(written by :class:`etmpc.views.recording.Recorder`, read back by :mod:`etmpc.views.replay`).

One episode lives under ``/<task>/<policy>/episode_<EEE>/repeat_<R>`` (``<task>``: the domain's
name for its default task, else ``<domain>-<task>``; ``<policy>``: the
policy's label, its spec with a learned policy's file shortened to its stem: ``every:3``,
``rl:learned``), so several episodes and policies in one file stay apart. Under it, every series
is a Rerun time series on two timelines, ``step`` (sequence) and ``time`` (seconds since the
episode started), and every series name carries its unit:

- ``identity``: static values: domain, task, policy (its exact spec), test-set episode, repeat,
  seed, test-set sha256, objective sense, price of a recompute, control interval; ``about``: a
  static title line (policy, episode, objective, recomputes, how to read the plots);
- ``realised/state/<name>``: the state, steps ``0..S``; ``realised/input/<name>``: the applied
  input, with its lower and upper bounds as two more series; ``realised/signal/<name>``: the
  episode's exogenous inputs (disturbance, or price and net production); ``correction/<name>``:
  the LQR correction added to the plan;
- ``plan/state/<name>``, ``plan/input/<name>``: every plan's prediction from the step it was made
  (up to the episode's end), as time series on the same timelines; ``forecast/<signal>``: every
  forecast a battery plan was made with, under the signal it forecasts. Each is one entity whose
  series are "slots": a plan takes the first slot whose last plan ended two steps before it
  starts, so the plans of a slot never overlap and a NaN row parts them. Each point is coloured
  by when its plan was made (``etmpc.views.blueprint.plan_colours``);
- ``decision``: ``recompute`` (1 where a recompute was started) and ``forced``, every step;
  ``recompute``: the recomputes only, as points at the age of the plan each one replaced, a
  series per kind (chosen by the policy, forced because the plan ran out, the first plan);
  ``events``: a log line per recompute (why, the plan's age, the prediction error);
- ``prediction_error``: ``‖W (x_i − x̂_i)‖`` against the plan in force before the step's decision
  (what the threshold policy compares; none at step 0, where there is no plan yet);
  ``threshold``: the threshold of a ``threshold:X`` policy;
- ``objective/reward`` (the environment's, per step) and ``objective/running`` (the running
  objective, recomputes included, in its own sense; a recompute's price is the identity's
  ``recompute_price`` times its work: ``compute``'s ``work`` where written, else ``decision``'s ``recompute``);
- a task with time in the loop (its identity has ``latency`` and ``compute_levels``): ``compute`` (each
  step's level, work and in flight), ``solve/in_force``, ``solve/started``, ``solve/arrived`` (the plan
  in force and each solve's start and arrival: ``etmpc.views.layout._solve_series``), ``events/solves``;
- a system with a 3-D scene (its ``space``): ``space/…``, the flight, each plan's and the target in 3-D (``etmpc.views.space``).

In one view, Rerun draws entities in the order of their paths: ``realised/…`` comes over
``plan/…`` and ``forecast/…``. The file carries a blueprint (``etmpc.views.blueprint``): a tab per
policy and episode. Each entity's whole series goes in with one ``send_columns`` call.
"""

from __future__ import annotations

from etmpc.views import blueprint as look

APPLICATION_ID = "etmpc"
END_MARKER = "/etmpc_recording_end"  # static, logged last: {"episodes": how many the file holds}
DECISION_SERIES = ("recompute", "forced")
COMPUTE_SERIES = ("level", "work", "in_flight")  # the columns of ``compute`` (etmpc.views.layout._solve_series)
OBJECTIVE_SERIES = ("reward", "computation", "running")


def episode_root(identity: dict, policy_part: str) -> str:
    task = look.task_part(identity["domain"], identity["task"])
    return f"/{task}/{policy_part}/episode_{int(identity['episode']):03d}/repeat_{int(identity['repeat'])}"
