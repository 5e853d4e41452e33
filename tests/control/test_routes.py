"""The route seam (etmpc.control.route): the table of routes is what the settings offer, the MPC picks its
route once from it, a route is made from the OCP value (never the MPC), and every route answers the protocol."""

import inspect

import numpy as np

from etmpc.control import route as routes
from etmpc.control.condensed import CondensedGaussNewton
from etmpc.control.mpc import GaussNewtonMPC
from etmpc.control.ocp import OCP
from etmpc.control.settings import ROUTES, SolverSettings
from etmpc.control.sqpmethod import SqpMethod


def test_the_settings_offer_exactly_the_routes_of_the_table():
    assert tuple(routes.ROUTE_CLASSES) == ROUTES
    assert routes.ROUTE_CLASSES == {"sqpmethod": SqpMethod, "condensed": CondensedGaussNewton}


def test_every_route_class_has_the_protocols_members_with_their_parameters():
    members = {name for name in dir(routes.Route) if not name.startswith("_")}
    assert members == {"is_compiled", "solve", "iterate", "warm_start", "prepare_iterations"}
    for cls in routes.ROUTE_CLASSES.values():
        assert list(inspect.signature(cls).parameters) == ["ocp", "settings", "feedback", "name"]
        for name in members - {"is_compiled"}:
            wanted = list(inspect.signature(getattr(routes.Route, name)).parameters)
            assert list(inspect.signature(getattr(cls, name)).parameters) == wanted, (cls, name)
        assert isinstance(inspect.getattr_static(cls, "is_compiled"), property)


def test_the_mpc_builds_the_ocp_once_and_hands_it_to_the_route_it_names(cart_system):
    ocp = cart_system.mpc.ocp
    for name, cls in routes.ROUTE_CLASSES.items():
        mpc = GaussNewtonMPC(
            ocp.model,
            ocp.stage_residual,
            ocp.terminal_residual,
            ocp.horizon,
            ocp.u_min,
            ocp.u_max,
            SolverSettings(route=name, compiled=False),
            name="cart_pendulum_mpc",
        )
        assert type(mpc.route) is cls and isinstance(mpc.ocp, OCP) and mpc.ocp is not ocp
        assert mpc.route.ocp is mpc.ocp
        assert mpc.solve(np.array([0.0, 0.0, 0.05, 0.0]), np.zeros(1)).success
