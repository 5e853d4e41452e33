"""A plan is the MPC's output value: what it intends to apply and what it predicts will happen."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from etmpc.common.frozen import frozen, readonly


@dataclass(frozen=True, eq=False)
class Plan:
    """An MPC solution made at step ``k`` from the measured state ``states[0]``.

    ``inputs[j]`` is the input planned for step ``k + j`` and ``states[j]`` the state predicted at
    ``k + j`` (``j = 0..N``). ``success`` is False when the solver did not converge; such a plan holds
    the solver's last iterate and is only used when there is no earlier plan to keep. ``cost`` is the
    value the solver minimised (for an economic MPC, the negative profit). ``forecasts`` holds the
    forecasts of time-varying parameters the plan was made with (name -> values for ``k..k+N-1``);
    ``gains`` the feedback gains along the plan, ``u = u_j - K_j (x - x_j)``, when its MPC computes them.

    A plan is a value: its arrays are read-only views and its forecasts a frozen mapping, so nothing
    it is handed to (a policy under test above all) can change what the loop applies.
    """

    inputs: np.ndarray  # (N, nu)
    states: np.ndarray  # (N + 1, nx)
    cost: float
    solve_time_s: float
    success: bool
    iterations: int = 0  # -1: the solver does not report it
    status: str = ""
    forecasts: Mapping[str, np.ndarray] = field(default_factory=dict)
    gains: np.ndarray | None = None  # (N, nu, nx): a time-varying LQR along the plan, if its MPC computes one

    def __post_init__(self):
        for name in ("inputs", "states", "gains"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, readonly(np.asarray(value)))
        object.__setattr__(self, "forecasts", frozen(self.forecasts))  # a plan's replace() keeps it as it is

    @property
    def converged(self) -> bool:
        """Whether the solver stopped within its tolerance (status ``"converged"``). A real-time iterate
        is usable (``success``) without being converged: how far it is, a policy deciding between one
        more iteration and keeping reads here (feature set ``levels``)."""
        return self.status == "converged"

    @property
    def horizon(self) -> int:
        return self.inputs.shape[0]

    def input_at(self, age: int) -> np.ndarray:
        """Planned input ``age`` steps after the plan was made (the last one past the horizon)."""
        return self.inputs[min(age, self.horizon - 1)]

    def state_at(self, age: int) -> np.ndarray:
        """Predicted state ``age`` steps after the plan was made (the terminal one past the horizon)."""
        return self.states[min(age, self.horizon)]

    def shifted(self, age: int) -> tuple[np.ndarray, np.ndarray]:
        """Inputs and states advanced by ``age`` steps, padded with the last values (a warm start)."""
        idx_u = np.minimum(np.arange(self.horizon) + age, self.horizon - 1)
        idx_x = np.minimum(np.arange(self.horizon + 1) + age, self.horizon)
        return self.inputs[idx_u], self.states[idx_x]
