"""Sample efficiency: each learner's test-objective gain over the best fixed schedule against the
environment steps it simulated to get there, the loop's and the rollouts' alike.

What one learner run (one seed) simulates, counted from what its files record:

* **GPOMDP** (the paper's): its training episodes, ``e T`` after ``e`` episodes, plus the coin-flip
  episodes that measure its feature normalisation;
* **DPI**: the same normalisation, the choice of ``pi_0`` (every candidate schedule played on the
  selection episodes), its training episodes, and at each labelled decision (step ``t``) both
  answers over ``K`` futures, ``2 K min(H, T - t)`` steps (the rollouts end with the episode; three
  answers on a task with compute levels);
* **PPO**: the steps its environments took, the reward baseline's lockstep simulation included
  (``training.json``'s ``simulated_steps``).

The y value is the paired gain over the best fixed schedule on the same test-set episodes (a curve
point of GPOMDP and DPI is the mean over their seeds; PPO's points are its checkpoints). The test set
only reports: every choice was made on training-distribution episodes.
"""

from __future__ import annotations

import numpy as np

from etmpc.evaluation.compare import per_episode
from etmpc.evaluation.metrics import oriented


def _gain(objective: float, reference: float, sense: str) -> float:
    """The gain over ``reference`` in percent of ``|reference|``, > 0: better."""
    return 100.0 * (oriented(objective, sense) - oriented(reference, sense)) / abs(reference)


def _reference(baselines: dict, best: str, episodes: int | None) -> float:
    values = per_episode(baselines, {best})
    chosen = sorted(values)[:episodes] if episodes else sorted(values)
    return float(np.mean([values[e] for e in chosen]))


def _normalisation(config: dict, steps: int) -> int:
    return int(config.get("normalisation_episodes", 0)) * steps


def gpomdp_points(checkpoint: dict, curve: dict, baselines: dict, best: str, sense: str, steps: int) -> list[dict]:
    """GPOMDP's curve: ``{"simulated_steps", "gain_percent", "episodes"}`` per evaluation (seeds' mean)."""
    config = checkpoint["config"]
    reference = _reference(baselines, best, config.get("eval_episodes"))
    return [
        {
            "episodes": p["episodes"],
            "simulated_steps": _normalisation(config, steps) + p["episodes"] * steps,
            "gain_percent": _gain(p["objective_mean"], reference, sense),
        }
        for p in curve["points"]
    ]


def dpi_points(checkpoint: dict, curve: dict, baselines: dict, best: str, sense: str, steps: int) -> list[dict]:
    """DPI's curve, as :func:`gpomdp_points`; a seed's rollouts counted from its labels' steps."""
    config, dpi = checkpoint["config"], checkpoint["config"]["dpi"]
    reference = _reference(baselines, best, config.get("eval_episodes"))
    start = _normalisation(config, steps) + len(dpi["bases"]) * dpi["selection_episodes"] * steps
    per_seed = []
    for seed in config["seeds"]:
        rows = iter(checkpoint["learners"][str(seed)]["data"])
        cost = {}  # episode -> the rollouts' steps of its labels
        for entry in (t for t in checkpoint["training"] if t["seed"] == seed):
            labels = [next(rows) for _ in range(entry["labels"])]
            # a row holds each answer's return: 2 (keep, solve), or 3 with q_iterate last on a task with compute levels
            cost[entry["episode"]] = sum((len(row) - 2) * dpi["futures"] * min(dpi["horizon"], steps - row[3]) for row in labels)
        per_seed.append(cost)
    points = []
    for p in curve["points"]:
        e = p["episodes"]
        rollouts = np.mean([sum(v for k, v in cost.items() if k < e) for cost in per_seed]) if e else 0.0
        points.append(
            {
                "episodes": e,
                "simulated_steps": int(round(start + e * steps + rollouts)),
                "gain_percent": _gain(p["objective_mean"], reference, sense),
            }
        )
    return points


def ppo_points(training: dict, evaluations: dict, baselines: dict, best: str, sense: str) -> list[dict]:
    """PPO's checkpoints: each one's gain on the test-set episodes it was evaluated on (``evaluations``:
    an evaluation JSON holding every checkpoint, as ``sb3:<run>/<file>``, and its run's folder prefix)."""
    points = []
    for c in training["checkpoints"]:
        spec = next(s for s in evaluations["policies"] if s.endswith(c["file"]))
        values = per_episode(evaluations, {spec})
        reference = per_episode(baselines, {best})
        common = sorted(set(values) & set(reference))
        objective, ref = np.mean([values[e] for e in common]), np.mean([reference[e] for e in common])
        points.append(
            {
                "timesteps": c["timesteps"],
                "simulated_steps": c.get("simulated_steps", c["timesteps"]),
                "wall_seconds": c["wall_seconds"],
                "gain_percent": _gain(float(objective), float(ref), sense),
            }
        )
    return points
