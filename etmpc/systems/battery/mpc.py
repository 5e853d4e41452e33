"""The economic MPC of the battery: a linear program solved by HiGHS through CasADi.

Over the horizon ``j = 0..N-1``, with forecasts ``P_j`` (kW) and ``lambda_j`` (EUR/kWh)::

    maximise    sum_j lambda_j u_j delta  +  lambda_bar C x_N                 (profit, EUR)
    subject to  x_{j+1} = x_j - delta/C (u_j - P_j),   0 <= x_{j+1} <= 1,   |u_j| <= 0.1 C / delta

The computer's own draw is not in the model (the plant draws it; the LQR and the recomputes absorb it: docs/paper.md). The
states are eliminated (``x_{j+1} = x_0 + delta/C sum_{i<=j} (P_i - u_i)``), which leaves ``N``
inputs, ``N`` two-sided cumulative-sum rows and the objective ``sum_j (lambda_j - lambda_bar) delta
u_j`` plus a constant. The inputs are scaled to ``[-1, 1]`` (the trade limit) so the LP's numbers
are of order one, and HiGHS runs without presolve, which costs more than it saves at this size.
A failed solve raises inside CasADi (``error_on_fail``); the solver's statistics are read only
then, because building them costs as much as a third of a successful solve.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from etmpc.systems.battery.parameters import Battery
from etmpc.control.plan import Plan


class EconomicMPC:
    """The trading LP; :meth:`solve` returns a :class:`Plan` whose ``cost`` is the negative profit."""

    def __init__(self, battery: Battery, horizon: int, terminal_price: float):
        if horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {horizon}")
        self.battery, self.horizon, self.terminal_price = battery, horizon, terminal_price
        self._limit = battery.trade_limit_kw
        self._per_kw = battery.soc_per_kw
        cumulative = np.tril(np.ones((horizon, horizon)))
        self._a = ca.DM(cumulative * self._per_kw * self._limit)  # SoC drop per unit of scaled input
        self._solver = ca.conic(
            "battery_lp",
            "highs",
            {"h": ca.Sparsity(horizon, horizon), "a": self._a.sparsity()},
            {"highs": {"output_flag": False, "presolve": "off"}, "error_on_fail": True},
        )

    def profit(self, soc: float, production_kw: np.ndarray, price: np.ndarray, inputs_kw: np.ndarray) -> float:
        """The LP's objective (EUR) of an input sequence; its SoC bounds are not checked here."""
        return self._profit(price, inputs_kw, self.rollout(soc, production_kw, inputs_kw)[-1])

    def _profit(self, price: np.ndarray, inputs_kw: np.ndarray, final_soc: float) -> float:
        return float(
            np.dot(price, inputs_kw) * self.battery.interval_h + self.terminal_price * self.battery.capacity_kwh * final_soc
        )

    def rollout(self, soc: float, production_kw: np.ndarray, inputs_kw: np.ndarray) -> np.ndarray:
        """Predicted states of charge ``x_0..x_N`` (the model knows no bounds)."""
        return np.concatenate(([soc], soc + self._per_kw * np.cumsum(production_kw - inputs_kw)))

    def solve(self, soc: float, production_kw: np.ndarray, price: np.ndarray) -> Plan:
        """Plan from state of charge ``soc`` with forecasts of length ``horizon``.

        If HiGHS reports anything but optimal, the plan holds the state of charge (each trade equals
        the forecast production, within the limit) and ``success`` is False.
        """
        n = self.horizon
        production_kw, price = np.asarray(production_kw, float)[:n], np.asarray(price, float)[:n]
        if production_kw.shape != (n,) or price.shape != (n,):
            raise ValueError(f"forecasts must have at least {n} values, got {production_kw.shape}, {price.shape}")
        start = time.perf_counter()
        inflow = soc + self._per_kw * np.cumsum(production_kw)  # SoC if nothing were traded
        try:
            solution = self._solver(
                g=-(price - self.terminal_price) * self.battery.interval_h * self._limit,
                a=self._a,
                lba=inflow - 1.0,
                uba=inflow,
                lbx=-1.0,
                ubx=1.0,
            )
            success, status = True, "optimal"
            inputs = np.clip(np.asarray(solution["x"]).ravel(), -1.0, 1.0) * self._limit
        except RuntimeError:
            success, status = False, str(self._solver.stats().get("return_status", "failed"))
            inputs = np.clip(production_kw, -self._limit, self._limit)
        states = self.rollout(soc, production_kw, inputs)
        return Plan(
            inputs=inputs[:, None],
            states=np.clip(states, 0.0, 1.0)[:, None],  # clip: solver round-off only
            cost=-self._profit(price, inputs, states[-1]),
            solve_time_s=time.perf_counter() - start,
            success=success,
            status=status,
            forecasts={"production_kw": production_kw, "price_eur_kwh": price},
        )
