"""A route: how the MPC's OCP (:class:`~etmpc.control.ocp.OCP`) is solved, behind one protocol, :class:`Route`.

:class:`~etmpc.control.mpc.GaussNewtonMPC` builds the OCP from its system, looks its route up by name
(``SolverSettings.route``) in :data:`ROUTE_CLASSES` once, when it is made, and from then on only asks
it. A route is given the OCP value, the solver settings, the feedback weights of the TV-LQR each plan
carries (or None) and a name for its compiled code: never the MPC. docs/routes.md says how to add one.

The routes:

* ``"sqpmethod"``: :class:`~etmpc.control.sqpmethod.SqpMethod`, CasADi's SQP on the multiple-shooting
  NLP, compiled to C or run in CasADi's virtual machine;
* ``"condensed"``: :class:`~etmpc.control.condensed.CondensedGaussNewton`, a Gauss-Newton SQP on the
  inputs alone, its dense QPs by DAQP.

``SolverSettings.route`` is chosen from :data:`~etmpc.control.settings.ROUTES`, the names of this table
(tests/control/test_routes.py holds them equal): the settings cannot import the table, whose routes read
the settings, without an import circle.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from etmpc.control.condensed import CondensedGaussNewton
from etmpc.control.ocp import OCP
from etmpc.control.plan import Plan
from etmpc.control.riccati import FeedbackWeights
from etmpc.control.settings import SolverSettings
from etmpc.control.sqpmethod import SqpMethod


class Route(Protocol):
    """What the MPC asks of a route. ``x``: the measured state; ``u_prev``: the input the first input change
    is against; ``warm``: the plan kept, made ``age`` steps ago (None: a cold start); ``parameters``: the
    OCP's other parameters (None when it has none)."""

    @property
    def is_compiled(self) -> bool:
        """Whether the route runs as compiled C (else in CasADi's virtual machine: the same plans, slower)."""
        ...

    def solve(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None) -> Plan:
        """A full solve, as fast as the route can make it."""
        ...

    def iterate(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None, limit: int
    ) -> Plan:
        """At most ``limit >= 1`` SQP iterations, counted one by one (``Plan.iterations``: the compute levels and
        a price or a latency per iteration read them), stopping when converged; ``limit=1`` is one real-time
        iteration, usable though not converged."""
        ...

    def warm_start(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, parameters: np.ndarray | None = None
    ) -> np.ndarray:
        """The first iterate, in the route's own variables: ``warm`` shifted by ``age``, or a cold guess."""
        ...

    def prepare_iterations(self) -> None:
        """Make (and build) now what :meth:`iterate` needs, so that no measured solve holds a one-off build."""
        ...


class RouteClass(Protocol):
    """A route's class: made from the OCP, the settings, the feedback weights and a name for its compiled code."""

    def __call__(self, ocp: OCP, settings: SolverSettings, feedback: FeedbackWeights | None, name: str) -> Route: ...


#: A route's name (``SolverSettings.route``) -> its class.
ROUTE_CLASSES: dict[str, RouteClass] = {"sqpmethod": SqpMethod, "condensed": CondensedGaussNewton}
