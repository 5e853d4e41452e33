"""The trading LP written out independently and solved by ``scipy.optimize.linprog``.

For tests and ``etmpc bench`` only: explicit state-of-charge variables, the dynamics as equality
constraints, physical units (kW, EUR), and scipy's own interface to HiGHS; nothing shared with
:mod:`etmpc.systems.battery.mpc` but the battery's constants.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import linprog

from etmpc.systems.battery.parameters import Battery


def solve_with_linprog(
    battery: Battery, terminal_price: float, soc: float, production_kw: np.ndarray, price: np.ndarray
) -> tuple[np.ndarray, float, bool]:
    """``(inputs_kw, profit_eur, success)`` of the LP: variables ``[u_0..u_{N-1}, x_1..x_N]``."""
    n = len(price)
    dt_h, per_kw, limit = battery.interval_h, battery.soc_per_kw, battery.trade_limit_kw
    cost = np.concatenate([-np.asarray(price) * dt_h, np.zeros(n)])
    cost[-1] = -terminal_price * battery.capacity_kwh  # maximise lambda_bar C x_N
    # x_{j+1} - x_j + per_kw u_j = per_kw P_j, with x_0 = soc moved to the right-hand side.
    a_eq = np.zeros((n, 2 * n))
    b_eq = per_kw * np.asarray(production_kw, float)
    for j in range(n):
        a_eq[j, j] = per_kw
        a_eq[j, n + j] = 1.0
        if j:
            a_eq[j, n + j - 1] = -1.0
    b_eq[0] += soc
    bounds = [(-limit, limit)] * n + [(0.0, 1.0)] * n
    result = linprog(cost, A_eq=a_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if result.status != 0:
        return np.full(n, np.nan), np.nan, False
    return result.x[:n], -float(result.fun), True


class LinprogReference:
    """The same LP for ``etmpc bench``: ``solve(x, u_prev, timestep, continuing)`` as the MPC sees it."""

    name = "scipy linprog (HiGHS)"

    def __init__(self, battery: Battery, horizon: int, terminal_price: float):
        self.battery, self.horizon, self.terminal_price = battery, horizon, terminal_price

    def solve(self, x, u_prev, timestep, continuing: bool) -> tuple[np.ndarray, float, bool]:
        obs = timestep.observation
        start = time.perf_counter()
        inputs, _, ok = solve_with_linprog(
            self.battery,
            self.terminal_price,
            float(x[0]),
            obs["production_forecast_kw"][: self.horizon],
            obs["price_forecast_eur_kwh"][: self.horizon],
        )
        return inputs, time.perf_counter() - start, ok
