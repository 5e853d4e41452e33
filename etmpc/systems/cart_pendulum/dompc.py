"""The cart-pendulum OCP solved with do-mpc 5.1 (the paper's original stack), for ``etmpc bench``.

do-mpc's conventions, checked against ``do_mpc/controller/_mpc.py`` (5.1.2, ``MPC._prepare_nlp``):

* discrete model: ``lterm(x_k, u_k)`` is summed over ``k = 0 .. N-1`` and ``mterm`` is evaluated
  once at ``x_N``, so ``lterm = beta^2, mterm = beta^2`` gives ``sum_{k<N} beta_k^2 + beta_N^2``;
* ``set_rterm(u=D)`` adds ``D (u_0 - u_prev)^2 + sum_{k=1}^{N-1} D (u_k - u_{k-1})^2``, where
  ``u_prev`` is ``mpc.u0`` at the time of ``make_step`` (``make_step`` overwrites ``mpc.u0`` with
  the first planned move afterwards; we set it explicitly every call);
* warm start: ``make_step`` starts Ipopt from the previous ``opt_x_num`` and multipliers
  (unshifted), which is how the paper's closed loop runs.

The objective therefore equals the etmpc OCP exactly (no scaling is set, so do-mpc's scaled and
unscaled variables coincide).
"""

from __future__ import annotations

import contextlib
import io
import time
import warnings

import casadi
import numpy as np

with warnings.catch_warnings():  # do-mpc warns about optional extras (ONNX, opcua, torch) on import
    warnings.simplefilter("ignore")
    import do_mpc


class DoMpcReference:
    """The cart-pendulum OCP of etmpc solved by do-mpc (Ipopt), for benchmarking only."""

    def __init__(
        self,
        discrete_model: casadi.Function,
        horizon: int,
        input_change_weight: float,
        u_min: float,
        u_max: float,
        angle_index: int = 2,
    ) -> None:
        """Build the do-mpc model and MPC for ``x+ = discrete_model(x, u)`` (4 states, 1 input)."""
        self.horizon = horizon
        model = do_mpc.model.Model("discrete", "SX")
        x = model.set_variable("_x", "x", shape=(4, 1))
        u = model.set_variable("_u", "u", shape=(1, 1))
        model.set_rhs("x", discrete_model(x, u))
        model.setup()

        mpc = do_mpc.controller.MPC(model)
        mpc.settings.n_horizon = horizon
        mpc.settings.t_step = 1.0  # bookkeeping only: the model is already discrete
        mpc.settings.store_full_solution = False
        mpc.settings.supress_ipopt_output()  # print_level 0, sb yes, print_time 0
        angle_sq = x[angle_index] ** 2
        mpc.set_objective(lterm=angle_sq, mterm=angle_sq)
        mpc.set_rterm(u=input_change_weight)
        mpc.bounds["lower", "_u", "u"] = u_min
        mpc.bounds["upper", "_u", "u"] = u_max
        # do-mpc's validity checks call numpy on casadi values (a casadi 3.8 FutureWarning).
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            mpc.setup()
        self._mpc = mpc
        self._first_call = True

    name = "do-mpc 5.1 (Ipopt)"

    def solve(self, x0: np.ndarray, u_prev, timestep=None, continuing: bool = True) -> tuple[np.ndarray, float, bool]:
        """Returns (inputs of shape (horizon,), wall-clock solve time in seconds of the make_step call, success).

        do-mpc always warm starts from its own previous solution, as in the paper's closed loop,
        so ``continuing`` (and the ``timestep``, which the cart's OCP does not need) are ignored.
        """
        mpc = self._mpc
        x0 = np.asarray(x0, dtype=float).reshape(4, 1)
        mpc.x0 = x0
        mpc.u0 = np.array([[float(np.ravel(u_prev)[0])]])
        if self._first_call:
            mpc.set_initial_guess()
            self._first_call = False
        t0 = time.perf_counter()
        mpc.make_step(x0)
        elapsed = time.perf_counter() - t0
        mpc.reset_history()  # make_step appends to mpc.data with np.append: keep it from growing
        inputs = np.array(casadi.vertcat(*mpc.opt_x_num["_u", :, 0]), dtype=float).ravel()
        return inputs, elapsed, bool(mpc.solver_stats["success"])
