"""How a recording reads in the Rerun viewer: series names with units, colours, and the blueprint.

The blueprint has a tab per policy and, inside it, a tab per recorded episode (the first
``MAX_EPISODE_TABS`` of each policy; the others are in the file too, in the entity tree). An
episode's tab holds a title line (the policy, the episode, its objective and recomputes, how to
read the plots) over three columns of time-series views, all on the same time axis, the whole
episode wide, on the ``step`` timeline:

- the states, each with what happened (thick, orange) and every plan's prediction from the step it
  was made (thin, coloured by when it was made: blue early, violet, teal, green late), and the
  exogenous signals that have forecasts, each with every forecast the controller was given;
- the inputs (applied, every plan's inputs, the bounds), the LQR correction, the other exogenous
  signals, and the prediction error ``‖W (x − x̂)‖`` (with a ``threshold:X`` policy's threshold);
- the recomputes (the age of the plan each one replaced, by kind), on a task with time in the loop
  the plan in force (with each solve's start and arrival) and each step's recompute (level, work,
  in flight), the reward per step, the running objective, and the recompute log (with each solve's
  start and arrival there);
- before them, for a system with a 3-D scene, a 3-D view of it (:mod:`etmpc.views.space`).

Each quantity has a panel of its own, so none flattens another; legends are off (they cover data)
and each panel's name says what its lines are. Rerun is imported only when a blueprint is built.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from etmpc.systems import spec
from etmpc.systems.base import system_type

MAX_EPISODE_TABS = 10  # per policy: each tab adds about 140 kB and 15 ms to a recording

# -- names ------------------------------------------------------------------------------------------
# What a name means on screen, with its unit. Names not listed get their unit from their suffix.
LABELS = {
    "cart_position": "cart position [m]",
    "cart_velocity": "cart velocity [m/s]",
    "pole_angle": "pole angle [rad]",
    "pole_angular_velocity": "pole angular velocity [rad/s]",
    "force_n": "force [N]",
    "disturbance_rad_s2": "angular disturbance w [rad/s²]",
    "state_of_charge": "state of charge [0–1]",
    "trade_kw": "trade [kW] (> 0 sells)",
    "price_eur_kwh": "price [EUR/kWh]",
    "net_production_kw": "net production [kW]",
}
_SUFFIX_UNITS = (
    ("_eur_kwh", "EUR/kWh"),
    ("_rad_s2", "rad/s²"),
    ("_rad_s", "rad/s"),
    ("_m_s", "m/s"),
    ("_kwh", "kWh"),
    ("_kw", "kW"),
    ("_rad", "rad"),
    ("_eur", "EUR"),
    ("_nm", "N m"),
    ("_n", "N"),
    ("_m", "m"),
    ("_s", "s"),
)


def objective_unit(domain: str, task: str) -> str:
    """The objective's unit of a task (its system's ``benchmark``; the cart pendulum's cost is a sum of
    squared pole angles, rad²)."""
    cls = system_type(f"{domain}/{task}")
    benchmark = cls.benchmark
    assert benchmark is not None  # every task of the suite has its benchmark.json beside its test set
    return benchmark.objective_unit


def task_part(domain: str, task: str) -> str:
    """A task's first entity-path part: ``DOMAIN-TASK``, its spec's slug (one path part)."""
    return spec(f"{domain}/{task}").slug


def label(name: str) -> str:
    """``pole_angle`` -> ``pole angle [rad]``; ``inflow_kw`` -> ``inflow [kW]``."""
    if name in LABELS:
        return LABELS[name]
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ')} [{unit}]"
    return f"{name.replace('_', ' ')} [-]"


def unit(name: str) -> str:
    """The unit in ``label(name)``'s brackets."""
    found = re.search(r"\[([^\]]*)\]", label(name))
    return found.group(1) if found else "-"


def policy_label(spec: str) -> str:
    """A policy's name on screen and in entity paths: its spec, with each learned or self-triggering
    policy's file path shortened to the file's stem (``rl:results/x/seed0/last.json`` -> ``rl:last``,
    ``self:runs/self.json`` -> ``self:self``)."""
    return re.sub(r"(rl|self):([^:]+?\.json)", lambda m: f"{m.group(1)}:{Path(m.group(2)).stem}", spec)


def signal_of_forecast(forecast: str, signals) -> str | None:
    """The signal a plan's forecast predicts: the signal of the same name, else the one whose name
    ends in it (the battery's ``production_kw`` forecasts its ``net_production_kw``)."""
    if forecast in signals:
        return forecast
    return next((s for s in signals if s.endswith("_" + forecast)), None)


# -- colours ----------------------------------------------------------------------------------------
# Mid-lightness colours, readable on the viewer's dark and light themes.
REALISED = (235, 94, 40)  # what happened: orange
BOUND = (140, 140, 140)  # input bounds, thresholds: grey
ESTIMATED = (60, 150, 220)  # the filter's estimate, where a sensor is not exact: blue
MEASURED = (170, 170, 170)  # the sensor's readings: light grey (absent where a state is not read)
CHOSEN = (66, 133, 244)  # a recompute the policy chose: blue
FORCED = (219, 68, 55)  # a recompute forced because the plan ran out: red
FIRST = (140, 140, 140)
ANNOUNCED = (15, 157, 88)  # what a self-trigger announced at a solve, a plan that came into force: green
ITERATION = (150, 90, 220)  # a recompute of one SQP iteration (compute levels): violet
# A plan's colour says when it was made: blue (episode start) -> violet -> teal -> green (end).
_PLAN_ANCHORS = np.array([(70, 110, 235), (150, 90, 220), (0, 165, 190), (70, 185, 60)], float)
PLAN_ALPHA = 210
REALISED_WIDTH, PLAN_WIDTH = 2.5, 1.0


def plan_colours(made: np.ndarray, steps: int) -> np.ndarray:
    """Packed RGBA (``uint32``) per plan, from when it was made (``made / steps`` in [0, 1])."""
    f = np.clip(np.asarray(made, float) / max(steps, 1), 0.0, 1.0) * (len(_PLAN_ANCHORS) - 1)
    i = np.minimum(f.astype(int), len(_PLAN_ANCHORS) - 2)
    w = (f - i)[:, None]
    rgb = np.rint(_PLAN_ANCHORS[i] * (1 - w) + _PLAN_ANCHORS[i + 1] * w).astype(np.uint32)
    return (rgb[:, 0] << 24) | (rgb[:, 1] << 16) | (rgb[:, 2] << 8) | np.uint32(PLAN_ALPHA)


# -- the layout -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EpisodeLayout:
    """What the blueprint needs to know of one recorded episode (the recorder keeps one per
    episode; entity paths are relative to ``root``)."""

    root: str
    domain: str  # the task's entity-path part (task_part): the domain's name for its default task
    policy: str  # the policy's label (see policy_label)
    episode: int
    repeat: int
    steps: int
    control_interval_s: float
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    signals: tuple[str, ...]  # exogenous signals without forecasts
    forecast_signals: tuple[str, ...]  # exogenous signals with forecasts
    entities: frozenset  # every entity path written under root, relative to it
    # Fixed y ranges by name. A forecast panel spans the true signal: forecasts may stray outside
    # it, and the viewer drops tick labels when it picks a tick step of 5·10^k (0.05 EUR/kWh).
    y_ranges: dict = field(default_factory=dict)
    objective_unit: str = "-"

    @property
    def tab_name(self) -> str:
        return f"episode {self.episode}" + (f", repeat {self.repeat}" if self.repeat else "")


def _time_series(name: str, layout: EpisodeLayout, parts: list[str], y_range=None):
    """A time-series view of the episode's entities ``parts`` (those it has), or None. Legends are
    off (they cover data): the view's name says what each line is."""
    import rerun.blueprint as rrb
    from rerun import TimeRange

    WHOLE = rrb.TimeRangeBoundary.infinite()  # noqa: N806

    contents = [f"{layout.root}/{p}" for p in parts if p in layout.entities]
    if not contents:
        return None
    return rrb.TimeSeriesView(
        name=name,
        origin=layout.root,
        contents=contents,
        # The whole episode (the viewer's default is a window around the time cursor, a minute wide
        # for the battery's 1000 s); zoom one panel in time and the others follow.
        axis_x=rrb.TimeAxis(view_range=TimeRange(start=WHOLE, end=WHOLE)),
        axis_y=rrb.ScalarAxis(range=y_range) if y_range is not None else None,
        plot_legend=rrb.PlotLegend(visible=False),
    )


ROWS = 3  # time-series panels per column: a fourth leaves too little height for the y axis' tick labels


def episode_container(layout: EpisodeLayout):
    """One episode: a title line over columns of three time-series views each, read column by
    column: the states and forecast signals; the inputs, the other signals and the prediction error;
    the recomputes and the objective; then the recompute log. (The viewer labels the y axis with
    steps of 10^k at least 20 px apart: at four panels a column on a 1000 px window, a series spanning
    0.8 gets one label.)"""
    import rerun.blueprint as rrb
    from rerun.blueprint.encodings import TextLogColumn, TimelineColumn

    view = lambda name, parts, **kw: _time_series(name, layout, parts, **kw)  # noqa: E731
    units = layout.objective_unit
    panels = [view(f"{label(s)} · thin: plans", [f"realised/state/{s}", f"plan/state/{s}"]) for s in layout.states]
    panels += [
        view(f"{label(s)} · thin: forecasts", [f"realised/signal/{s}", f"forecast/{s}"], y_range=layout.y_ranges.get(s))
        for s in layout.forecast_signals
    ]
    panels += [
        view(f"{label(u)} · thin: plans · grey: bounds", [f"realised/input/{u}", f"plan/input/{u}", f"bound/{u}"])
        for u in layout.inputs
    ]
    panels += [view(f"LQR correction added to the plan [{unit(u)}]", [f"correction/{u}"]) for u in layout.inputs]
    panels += [view(label(s), [f"realised/signal/{s}"]) for s in layout.signals]
    panels += [
        view(
            "prediction error ‖W (x − x̂)‖" + (" · grey: threshold" if "threshold" in layout.entities else ""),
            ["prediction_error", "threshold"],
        ),
        view(
            "recomputes (● chosen ✕ forced ◆ first): age of the plan replaced [steps]"
            + (" · ▲ announced at the solve" if "announced" in layout.entities else ""),
            ["recompute", "announced"],
        ),
        view(
            "plan in force: the step it was made for [step] · ● solve started ▲ plan in force ✕ no plan",
            ["solve/in_force", "solve/started", "solve/arrived"],
        ),
        view("recompute per step: level (1 one SQP iteration, 2 full solve), work, in flight", ["compute"]),
        view(f"reward per step [{units}]", ["objective/reward"]),
        view(f"running objective [{units}], recomputes included", ["objective/running"]),
    ]
    panels = [v for v in panels if v is not None]
    if "camera" in layout.entities:
        panels.insert(0, rrb.Spatial2DView(name="camera", origin=f"{layout.root}/camera"))
    columns = [panels[i : i + ROWS] for i in range(0, len(panels), ROWS)]
    shares = [3] * len(columns)
    if "space" in layout.entities:  # a 3-D view of the flight (etmpc.views.space), a column two wide of its own, first
        name = "3-D, z up [m] · orange: what happened · thin: the plan in force · red: target · yellow: force · grey: box"
        columns.insert(0, [rrb.Spatial3DView(name=name, origin=f"{layout.root}/space")])
        shares.insert(0, 6)
    if "events" in layout.entities:
        log = rrb.TextLogView(
            name="recomputes",
            origin=f"{layout.root}/events",
            columns=rrb.TextLogColumns(
                timeline_columns=[TimelineColumn("step"), TimelineColumn("time")],
                text_log_columns=[
                    TextLogColumn("loglevel", visible=False),
                    TextLogColumn("body"),
                    TextLogColumn("entitypath", visible=False),
                ],
            ),
        )
        if len(columns[-1]) < ROWS:  # the last column has room
            columns[-1].append(log)
        else:
            columns.append([log])
            shares.append(2)
    body = rrb.Horizontal(*[rrb.Vertical(*views) for views in columns], column_shares=shares)
    title = rrb.TextDocumentView(name=f"{layout.policy}, {layout.tab_name}", origin=f"{layout.root}/about", titlebar=False)
    return rrb.Vertical(title, body, row_shares=[1, 13], name=layout.tab_name)


def blueprint(layouts: list[EpisodeLayout]):
    """Tabs per policy, each with a tab per episode (the first ``MAX_EPISODE_TABS``)."""
    import rerun.blueprint as rrb

    by_policy: dict[tuple[str, str], list[EpisodeLayout]] = {}
    for layout in layouts:
        by_policy.setdefault((layout.domain, layout.policy), []).append(layout)
    domains = {domain for domain, _ in by_policy}
    tabs = []
    for (domain, policy), group in by_policy.items():
        episodes = [episode_container(layout) for layout in group[:MAX_EPISODE_TABS]]
        name = policy if len(domains) == 1 else f"{domain}: {policy}"
        tabs.append(rrb.Tabs(*episodes, name=name) if len(episodes) > 1 else _renamed(episodes[0], name))
    root = tabs[0] if len(tabs) == 1 else rrb.Tabs(*tabs)
    # Opens on the step timeline: its ticks (#0, #10, …) are labelled plainly; the time panel's
    # timeline menu switches to `time`, in seconds.
    return rrb.Blueprint(root, rrb.TimePanel(state="collapsed", timeline="step"), collapse_panels=True)


def _renamed(container, name: str):
    container.name = name
    return container
