"""One-step prediction error of the analytic model (the MPC's predictor) against the MuJoCo plant.

From states drawn like the episodes' initial states and inputs drawn uniformly within the force
limits, the plant runs one control interval with no disturbance (so the error is the model's
alone) and the predictor predicts the same interval.
"""

from __future__ import annotations

import numpy as np

from etmpc.systems.cart_pendulum import task as cp_env
from etmpc.systems.cart_pendulum.model import NX, AnalyticModel


def one_step_errors(plant: str, samples: int, rng: np.random.Generator, model: AnalyticModel = AnalyticModel()) -> np.ndarray:
    """``(samples, 4)`` errors ``x_plant - x_predicted`` after one 0.1 s interval."""
    environment = cp_env.make_environment(plant=plant)
    physics = environment.physics
    errors = np.empty((samples, NX))
    for n in range(samples):
        x = rng.uniform(cp_env.INITIAL_STATE_LOW - [1, 0, 0, 0], cp_env.INITIAL_STATE_HIGH + [1, 0, 0, 0])
        u = rng.uniform(-25.0, 25.0)
        with physics.reset_context():
            physics.set_state_vector(x)
            physics.set_disturbance(0.0)
        physics.set_control([u])
        physics.step(environment._n_sub_steps)  # one control interval, as control.Environment does
        errors[n] = physics.state() - model.predict(x, np.array([u]))
    return errors


def table(samples: int = 500, seed: int = 0) -> list[dict]:
    """RMS and max |error| per state component, for each plant setting."""
    rows = []
    for plant in cp_env.PLANTS[::-1]:  # matched first
        err = one_step_errors(plant, samples, np.random.default_rng(seed))
        rows.append({"plant": plant, "rms": np.sqrt(np.mean(err**2, axis=0)), "max": np.max(np.abs(err), axis=0)})
    return rows
