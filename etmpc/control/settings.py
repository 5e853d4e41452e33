"""How an MPC's OCP is solved: :class:`SolverSettings`, read by :class:`~etmpc.control.mpc.GaussNewtonMPC`
and its routes (:mod:`etmpc.control.route`); and the declarations the controllers' settings share
(:func:`horizon_setting`, :func:`weight_setting`, ...), each an option with its range (:mod:`etmpc.common.declared`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from etmpc.common.checks import BadValue
from etmpc.common.declared import Checked, setting

#: The routes ``SolverSettings.route`` may name: the names of :data:`etmpc.control.route.ROUTE_CLASSES`, which maps
#: each to its class (tests/control/test_routes.py holds them equal; this module cannot import that table, whose
#: routes read these settings, without an import circle).
ROUTES = ("sqpmethod", "condensed")
COLD_STARTS = ("rollout", "hold")
#: The QP solvers sqpmethod may use: CasADi plugins that this project tests on its OCPs (tests/control/test_mpc.py
#: solves one with each). A name is chosen from this list, never passed on: CasADi loads a plugin it does not find
#: in its own folder from the working folder, so a name it does not ship would run whatever library lies there.
#: Left out: daqp (its SQP fails on these Gauss-Newton QPs: 262 failures in 2 kicks episodes), hpipm (it needs a
#: stage structure the shooting blocks do not have) and proxqp (its QPs stop short of the SQP's 1e-8 tolerance).
QP_SOLVERS = ("qrqp", "qpoases", "osqp", "highs")
#: The longest horizon an option may ask for: N = 100 builds and plays one kicks episode in 94 s here (its
#: compiled C most of it), and the work grows faster than N.
MAX_HORIZON = 100
MAX_RK4_SUBSTEPS = 20
#: The largest weight of a cost or a feedback design: weights are ratios, and 1e6 is beyond any tuning here.
MAX_WEIGHT = 1e6
MIN_INPUT_WEIGHT = 1e-6  # the least weight on an LQR's inputs: R > 0, and its gain stays finite


def horizon_setting(default: int) -> Any:
    """A controller's horizon, as an option."""
    return setting(
        default,
        low=1,
        high=MAX_HORIZON,
        unit="intervals",
        why="the MPC's horizon N: its OCP, its compiled code and its solve grow with it",
    )


def rk4_setting(default: int) -> Any:
    """The RK4 steps of a predictor per control interval, as an option."""
    return setting(
        default,
        low=1,
        high=MAX_RK4_SUBSTEPS,
        why="RK4 steps of the MPC's predictor per control interval: the OCP's size grows with them",
    )


def weight_setting(default: Any, why: str, lengths: tuple[int, ...] | None = None) -> Any:
    """A cost's weight (or one per state: ``lengths``), as an option: 0 turns its term off."""
    return setting(default, low=0, high=MAX_WEIGHT, lengths=lengths, why=why)


def input_weight_setting(default: Any, why: str, lengths: tuple[int, ...] | None = None) -> Any:
    """An LQR's weight on its inputs (R), as an option: > 0, or the design has no gain."""
    return setting(default, low=MIN_INPUT_WEIGHT, high=MAX_WEIGHT, lengths=lengths, why=f"{why}: > 0, or the design has no gain")


def levels_setting(default: bool) -> Any:
    """Whether a decision chooses how much to compute, as an option."""
    return setting(default, why="a decision is keep, one SQP iteration or a full solve, priced per iteration")


def check_block(block: int, horizon: int) -> None:
    """Shooting nodes every ``block`` intervals fit in a horizon of ``horizon`` (each is in range alone): checked
    where the system is made and where an MPC is built, with one message."""
    if block > horizon:
        raise BadValue(f"option solver.block: {block} is longer than the horizon of {horizon} intervals")


def plugin_library(kind: str, name: str) -> Path:
    """CasADi's own library of plugin ``name`` of ``kind`` (``conic``, ``nlpsol``), which must exist: CasADi
    would look for one it does not have in the working folder (and load whatever lies there)."""
    import casadi as ca

    folder = Path(ca.__file__).parent
    found = [p for p in folder.glob(f"libcasadi_{kind}_{name}.*") if p.suffix in (".so", ".dylib", ".dll") or ".so." in p.name]
    if not found:
        raise BadValue(f"this CasADi ({folder}) has no {kind} plugin {name!r}: it cannot be used")
    return found[0]


@dataclass(frozen=True)
class SolverSettings(Checked):
    """How an MPC's OCP is solved. ``route``: ``"sqpmethod"`` (:mod:`etmpc.control.sqpmethod`: CasADi's SQP on the
    multiple-shooting NLP, its QPs by ``qpsol``: reads ``tolerance``, ``dual_tolerance``, ``qpsol``, ``qpsol_options``,
    ``block``, ``sqp_options``, ``cold_start``) or ``"condensed"`` (:mod:`etmpc.control.condensed`: a Gauss-Newton SQP
    on the inputs alone, its dense QPs by DAQP; reads ``step_tolerance``). Both read ``max_iterations``,
    ``regularisation``, ``compiled`` and ``warm_from_expired``. ``qpsol_options`` and ``sqp_options`` are set in
    code, never as options."""

    tolerance: float = setting(1e-8, above=0, high=1, why="sqpmethod's tolerance on the primal (and dual) residual")
    max_iterations: int = setting(100, low=1, high=1000, unit="iterations", why="SQP iterations per solve at most")
    qpsol: str = setting("qrqp", choices=QP_SOLVERS, why="sqpmethod's QP solver, among the CasADi plugins tested here")
    qpsol_options: tuple[tuple[str, object], ...] = ()
    # shooting nodes every `block` intervals (1: full multiple shooting)
    block: int = setting(4, low=1, high=MAX_HORIZON, unit="intervals", why="shooting nodes every this many intervals")
    compiled: bool = setting(True, why="the solve as generated C, built once per machine (false: CasADi's virtual machine)")
    dual_tolerance: float | None = None  # sqpmethod tol_du (None: tolerance)
    regularisation: float = setting(
        0.0, low=0, high=1e6, why="mu I added to the Gauss-Newton Hessian (Levenberg-Marquardt); 0: none"
    )
    sqp_options: tuple[tuple[str, object], ...] = ()  # more sqpmethod options (merit_memory, max_iter_ls, ...)
    # A cold start's guess: "rollout" (zero inputs, the predictor's states from x) or "hold" (zero
    # inputs, every state x). Near an unstable equilibrium "hold" stays near it, where a rollout of
    # zero inputs falls away and can lead the SQP to another optimum (a pole swung over the top).
    cold_start: str = setting("rollout", choices=COLD_STARTS, why="a cold start's guess: the predictor's rollout or x held")
    warm_from_expired: bool = setting(True, why="a plan kept to its end still warm-starts the next solve")
    route: str = setting("sqpmethod", choices=ROUTES, why="how the OCP is solved: CasADi's sqpmethod or the condensed SQP")
    # The condensed route has converged when the QP's step moves no input by more than this share of its range.
    step_tolerance: float = setting(
        1e-3, above=0, high=1, why="the condensed route stops when no input moves by more than this share of its range"
    )
