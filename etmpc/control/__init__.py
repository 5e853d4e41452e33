"""The parts a controller is made of: the plan (:mod:`~etmpc.control.plan`, the MPC's output as a
frozen value), the Gauss-Newton MPC (:mod:`~etmpc.control.mpc`) and the CasADi functions it runs as
compiled C (:mod:`~etmpc.control.compiled`), and the LQR feedback on the prediction error
(:mod:`~etmpc.control.lqr`), and the RK4 that makes a model's ODE a predictor
(:mod:`~etmpc.control.discretise`). Generic: no task is named here; each system builds its controller
from these parts.

This package may import ``etmpc.common``.
"""
