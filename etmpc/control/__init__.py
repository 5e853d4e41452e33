"""The parts a controller is made of: the plan (:mod:`~etmpc.control.plan`, the MPC's output as a
frozen value), the Gauss-Newton MPC (:mod:`~etmpc.control.mpc`), the OCP it solves as a value
(:mod:`~etmpc.control.ocp`) and the routes that solve it (:mod:`~etmpc.control.route`: the protocol and the
table; :mod:`~etmpc.control.sqpmethod`, :mod:`~etmpc.control.condensed`), the CasADi functions they run as
compiled C (:mod:`~etmpc.control.compiled`), and the LQR feedback on the prediction error
(:mod:`~etmpc.control.lqr`), and the RK4 that makes a model's ODE a predictor
(:mod:`~etmpc.control.discretise`). Generic: no task is named here; each system builds its controller
from these parts.

This package may import ``etmpc.common``.
"""
