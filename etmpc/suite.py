"""The etmpc tasks, loaded as ``dm_control.suite`` loads its own (see :mod:`etmpc.systems.suite`).

>>> env = etmpc.suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
"""

from etmpc.systems.suite import ALL_TASKS, BENCHMARKING, TASKS_BY_DOMAIN, UnknownSuiteNameError, domains, load, tasks

__all__ = ["ALL_TASKS", "BENCHMARKING", "TASKS_BY_DOMAIN", "UnknownSuiteNameError", "domains", "load", "tasks"]
