"""Rerun recordings of episodes, and reading them back.

One episode lives under ``/<domain>/<policy>/episode_<EEE>/repeat_<R>``, so several episodes and
policies in one file stay apart. Under it:

- ``identity``: static values: domain, task, policy (its exact spec), test-set episode, repeat,
  seed, test-set sha256, objective sense, price of a computation, control interval;
- ``state`` (a series per state), ``input`` (planned, LQR correction and applied, per input) and
  ``signal`` (the episode's exogenous inputs: disturbance, or price and net production): time
  series, one entity each with a named series per column;
- ``decision``: ``recompute`` (1 where a computation was spent) and ``forced``; ``events``: a text
  log line per recompute;
- ``prediction_error``: ``‖W (x_i − x̂_i)‖`` against the plan in force before the step's decision
  (what the threshold policy compares; none at step 0, where there is no plan yet);
- ``objective``: ``reward`` (the environment's, per step), ``computation`` (the price of the
  step's computation) and ``running`` (the running objective, in its own sense);
- ``plan/state/<name>`` and ``plan/input/<name>``: each new plan, at the step it was made, as a
  line from that step into the future (x: time in seconds); ``forecast/<name>``: the forecasts a
  battery plan was made with; ``realised/state/<name>``, ``realised/signal/<name>``: the whole
  realised trajectory as a static line, to set the plans against.

Two timelines: ``step`` (sequence) and ``time`` (seconds since the episode started). A blueprint
for the first recorded episode ships in the file. The whole series of an episode goes in with
``send_columns``, one call per entity.

``read_recording`` reads a file back with Rerun's own reader, and ``replay_summary`` recomputes
each episode's figures from it with the same formulas as the live run.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from etmpc.errors import EtmpcError

APPLICATION_ID = "etmpc"
# Column order of the multi-series entities.
INPUT_SERIES = ("planned", "LQR correction", "applied")
DECISION_SERIES = ("recompute", "forced")
OBJECTIVE_SERIES = ("reward", "computation", "running")


@dataclass(frozen=True, eq=False)
class EpisodeRecord:
    """What a recording keeps of one episode: small, picklable, built on the worker that ran it."""

    identity: dict
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    error_weights: np.ndarray
    states: np.ndarray  # (S + 1, nx)
    planned: np.ndarray  # (S, nu)
    correction: np.ndarray  # (S, nu)
    applied: np.ndarray  # (S, nu)
    recompute: np.ndarray  # (S,) bool
    forced: np.ndarray  # (S,) bool
    rewards: np.ndarray  # (S,)
    prediction_error: np.ndarray  # (S,), NaN at step 0
    plans: list = field(default_factory=list)  # (step, states (N+1, nx), inputs (N, nu), forecasts {name: (N,)})
    signals: dict = field(default_factory=dict)  # name -> (>= S,)

    @property
    def steps(self) -> int:
        return len(self.rewards)

    @classmethod
    def from_trajectory(cls, system, traj, identity: dict, episode) -> EpisodeRecord:
        n = traj.steps
        return cls(
            identity=dict(identity, domain=system.domain, task=system.task, objective_sense=system.objective_sense,
                          recompute_price=float(system.recompute_price), control_interval_s=float(system.control_interval_s)),
            state_names=tuple(system.state_names),
            input_names=tuple(system.input_names),
            error_weights=np.asarray(system.error_weights, float),
            states=traj.states[: n + 1].copy(),
            planned=traj.planned[:n].copy(),
            correction=traj.correction[:n].copy(),
            applied=traj.applied[:n].copy(),
            recompute=traj.recompute[:n].copy(),
            forced=traj.forced[:n].copy(),
            rewards=traj.rewards[:n].copy(),
            prediction_error=prediction_errors(traj, system.error_weights),
            plans=[(k, p.states, p.inputs, {name: np.asarray(v) for name, v in p.forecasts.items()}) for k, p in traj.plans],
            signals={name: np.asarray(v, float) for name, v in system.signals(episode).items()},
        )


def prediction_errors(traj, error_weights) -> np.ndarray:
    """``‖W (x_i − x̂_i)‖`` per step, ``x̂_i`` from the plan in force before step i's decision."""
    errors = np.full(traj.steps, np.nan)
    plans = iter(traj.plans)
    current, upcoming = None, next(plans, None)
    w = np.asarray(error_weights, float)
    for i in range(traj.steps):
        if current is not None:
            k, plan = current
            errors[i] = float(np.linalg.norm(w * (traj.states[i] - plan.state_at(i - k))))
        while upcoming is not None and upcoming[0] <= i:  # a plan made at step i is in force from i on
            current, upcoming = upcoming, next(plans, None)
    return errors


def slug(text: str) -> str:
    """An entity-path part for a policy spec: ``every:3`` -> ``every_3``."""
    return re.sub(r"[^A-Za-z0-9_]+", "_", text).strip("_") or "policy"


def episode_root(identity: dict, policy_part: str) -> str:
    return f"/{identity['domain']}/{policy_part}/episode_{int(identity['episode']):03d}/repeat_{int(identity['repeat'])}"


class Recorder:
    """Writes episodes into one ``.rrd`` file. The file appears under its name only once it is
    complete: it is written beside it and renamed on ``close``."""

    def __init__(self, path: str | Path):
        import rerun as rr

        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise EtmpcError(f"a recording is a .rrd file, got {self.path}")
        if self.path.is_dir():
            raise EtmpcError(f"{self.path} is a directory, not a file")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.partial")
        self._rr = rr
        self._stream = rr.RecordingStream(APPLICATION_ID)
        self._stream.save(self._tmp)
        self._policy_parts: dict[tuple[str, str], str] = {}
        self._blueprint_sent = False
        self.episodes = 0

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(keep=exc_type is None)

    def close(self, keep: bool = True) -> None:
        try:
            if keep:  # the end marker: a reader that does not find it knows the file was cut short
                self._stream.log(END_MARKER, self._rr.AnyValues(episodes=self.episodes), static=True)
            self._stream.flush()
            self._stream.disconnect()
            if keep:
                self._tmp.replace(self.path)
        except (OSError, RuntimeError) as exc:  # RuntimeError: Rerun's file writer gave up (a full disk)
            keep = False
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise EtmpcError(f"cannot write {self.path}: {reason} (is the disk full?)") from None
        finally:
            if not keep:
                self._tmp.unlink(missing_ok=True)

    def _policy_part(self, domain: str, policy: str) -> str:
        key = (domain, policy)
        if key not in self._policy_parts:
            part, taken = slug(policy), set(self._policy_parts.values())
            i = 2
            while part in taken:  # two specs with the same slug stay apart
                part, i = f"{slug(policy)}_{i}", i + 1
            self._policy_parts[key] = part
        return self._policy_parts[key]

    def log_episode(self, record: EpisodeRecord, frames: Iterable[np.ndarray] | None = None) -> str:
        """Log one episode (and, optionally, rendered frames, one per state); returns its root path."""
        rr, stream = self._rr, self._stream
        identity = record.identity
        root = episode_root(identity, self._policy_part(identity["domain"], identity["policy"]))
        dt = identity["control_interval_s"]
        n = record.steps
        state_index = _timeline(np.arange(n + 1), dt)
        step_index = _timeline(np.arange(n), dt)

        stream.log(f"{root}/identity", rr.AnyValues(**identity), static=True)
        # Series that share an index go in one entity, a column each: the index (row id, step,
        # time) costs more than a value, so this keeps files small.
        _series(stream, f"{root}/state", state_index, record.states, record.state_names)
        for j, name in enumerate(record.state_names):
            stream.log(f"{root}/realised/state/{name}", rr.LineStrips2D([np.c_[np.arange(n + 1) * dt, record.states[:, j]]]),
                       static=True)
        inputs = np.concatenate([record.planned, record.correction, record.applied], axis=1)
        names = [f"{kind}: {name}" for kind in INPUT_SERIES for name in record.input_names]
        _series(stream, f"{root}/input", step_index, inputs, names)
        if record.signals:
            signals = np.stack([values[:n] for values in record.signals.values()], axis=1)
            _series(stream, f"{root}/signal", step_index, signals, list(record.signals))
            for j, name in enumerate(record.signals):
                stream.log(f"{root}/realised/signal/{name}", rr.LineStrips2D([np.c_[np.arange(n) * dt, signals[:, j]]]),
                           static=True)

        decisions = np.stack([record.recompute, record.forced], axis=1).astype(float)
        _series(stream, f"{root}/decision", step_index, decisions, DECISION_SERIES, points=True)
        events = np.flatnonzero(record.recompute)
        if len(events):
            text = ["first plan" if i == 0 else "forced recompute: the plan ran out" if record.forced[i] else "recompute"
                    for i in events]
            stream.send_columns(f"{root}/events", _timeline(events, dt), rr.TextLog.columns(text=text, level=["INFO"] * len(text)))
        known = np.flatnonzero(np.isfinite(record.prediction_error))
        _series(stream, f"{root}/prediction_error", _timeline(known, dt), record.prediction_error[known, None], ["‖W (x − x̂)‖"])

        price = identity["recompute_price"] * record.recompute
        sign = 1.0 if identity["objective_sense"] == "max" else -1.0
        objective = np.stack([record.rewards, price, sign * np.cumsum(record.rewards - price)], axis=1)
        _series(stream, f"{root}/objective", step_index, objective, OBJECTIVE_SERIES)

        if record.plans:
            made = np.array([k for k, *_ in record.plans])
            plan_index = _timeline(made, dt)
            states = np.stack([states for _, states, _, _ in record.plans])  # (P, N + 1, nx)
            inputs = np.stack([inputs for _, _, inputs, _ in record.plans])  # (P, N, nu)
            for j, name in enumerate(record.state_names):
                stream.send_columns(f"{root}/plan/state/{name}", plan_index, _strips(made, states[:, :, j], dt))
            for j, name in enumerate(record.input_names):
                stream.send_columns(f"{root}/plan/input/{name}", plan_index, _strips(made, inputs[:, :, j], dt))
            for name in record.plans[0][3]:
                forecast = np.stack([f[name] for _, _, _, f in record.plans])  # (P, N)
                stream.send_columns(f"{root}/forecast/{name}", plan_index, _strips(made, forecast, dt))

        if frames is not None:
            for i, frame in enumerate(frames):
                stream.set_time("step", sequence=i)
                stream.set_time("time", duration=i * dt)
                stream.log(f"{root}/camera", rr.Image(frame).compress(jpeg_quality=85))

        if not self._blueprint_sent:
            stream.send_blueprint(blueprint(root, record))
            self._blueprint_sent = True
        self.episodes += 1
        return root


def _series(stream, entity: str, index: list, values: np.ndarray, names, points: bool = False) -> None:
    import rerun as rr

    stream.send_columns(entity, index, rr.Scalars.columns(scalars=np.asarray(values, float)))
    style = rr.SeriesPoints(names=list(names), marker_sizes=[3.0] * len(names)) if points else rr.SeriesLines(names=list(names))
    stream.log(entity, style, static=True)


def _strips(made: np.ndarray, values: np.ndarray, dt: float):
    """A line per row of ``values (P, L)``, from the step it was made at into the future: points
    ``((k + j) dt, values[p, j])``."""
    import rerun as rr

    points = np.empty(values.shape + (2,), dtype=np.float32)
    points[..., 0] = (made[:, None] + np.arange(values.shape[1])) * dt
    points[..., 1] = values
    return rr.LineStrips2D.columns(strips=points)  # a 3-D array takes Rerun's numpy fast path


def _timeline(steps: np.ndarray, dt: float) -> list:
    import rerun as rr

    steps = np.asarray(steps, dtype=np.int64)
    # Whole nanoseconds as timedelta64: exact, and Rerun's fast path (floats go element by element).
    return [rr.TimeColumn("step", sequence=steps),
            rr.TimeColumn("time", duration=(steps * round(dt * 1e9)).astype("timedelta64[ns]"))]


def blueprint(root: str, record: EpisodeRecord):
    """The layout the file opens in: one episode's series on the left, its plans against what
    happened on the right."""
    import rerun.blueprint as rrb

    series = [
        rrb.TimeSeriesView(name="state", origin=f"{root}/state"),
        rrb.TimeSeriesView(name="input: planned, LQR correction, applied", origin=f"{root}/input"),
        rrb.TimeSeriesView(name="prediction error and recomputes", contents=[f"{root}/prediction_error", f"{root}/decision"]),
        rrb.TimeSeriesView(name="reward, computation, running objective", origin=f"{root}/objective"),
    ]
    if record.signals:
        series.append(rrb.TimeSeriesView(name="exogenous signals", origin=f"{root}/signal"))
    plans = [rrb.Spatial2DView(name=f"plans: {name}", contents=[f"{root}/plan/state/{name}", f"{root}/realised/state/{name}"])
             for name in record.state_names]
    plans += [rrb.Spatial2DView(name=f"forecasts: {name}", contents=[f"{root}/forecast/{name}", f"{root}/realised/signal/{name}"])
              for name in (record.plans[0][3] if record.plans else {})]
    right = plans + [rrb.TextLogView(name="recompute events", origin=f"{root}/events")]
    return rrb.Blueprint(rrb.Horizontal(rrb.Vertical(*series), rrb.Vertical(*right)), collapse_panels=True)


# -- reading back ------------------------------------------------------------------------------------
END_MARKER = "/etmpc_recording_end"  # static, logged last: {"episodes": how many the file holds}
READ = {"objective": OBJECTIVE_SERIES, "decision": DECISION_SERIES, "prediction_error": ("prediction_error",)}


def read_recording(path: str | Path) -> dict[str, dict]:
    """``{episode root: {"identity": {...}, "reward": (steps, values), "recompute": …, "forced": …,
    "computation": …, "running": …, "prediction_error": …}}`` from a ``.rrd`` file, read with
    Rerun's own reader."""
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise EtmpcError(f"recording {path} not found")
    with warnings.catch_warnings(record=True) as caught:  # said in the error below, not as a second line
        warnings.simplefilter("always")
        try:
            chunks = list(RrdReader(str(path)).stream())
        except Exception as exc:  # the reader raises its own types for a file that is not a recording
            short = any("no footer" in str(w.message) for w in caught)
            raise EtmpcError(f"recording {path} is cut short (no footer; {exc})" if short else
                             f"{path} is not a readable Rerun recording ({exc})") from None
    episodes: dict[str, dict] = {}
    pieces: dict[tuple[str, str], list] = {}
    end = None
    for chunk in chunks:
        if str(chunk.entity_path) == END_MARKER and chunk.is_static:
            batch = chunk.to_record_batch()
            end = int(batch.column("episodes").to_pylist()[0][0])
            continue
        root, _, leaf = str(chunk.entity_path).rpartition("/")
        if leaf != "identity" and leaf not in READ:
            continue
        batch = chunk.to_record_batch()
        if leaf == "identity" and chunk.is_static:
            identity = {name: batch.column(name).to_pylist()[0][0] for name in batch.schema.names if not name.startswith("rerun.")}
            episodes.setdefault(root, {})["identity"] = identity
        elif leaf in READ and "Scalars:scalars" in batch.schema.names:
            values = batch.column("Scalars:scalars").flatten().to_numpy().reshape(batch.num_rows, len(READ[leaf]))
            pieces.setdefault((root, leaf), []).append((batch.column("step").to_numpy(), values))
    for (root, leaf), parts in pieces.items():
        steps = np.concatenate([s for s, _ in parts])
        values = np.concatenate([v for _, v in parts])
        order = np.argsort(steps, kind="stable")
        for j, name in enumerate(READ[leaf]):
            episodes.setdefault(root, {})[name] = (steps[order], values[order, j])
    complete = {root: data for root, data in episodes.items() if "identity" in data and "reward" in data}
    if end is None:
        raise EtmpcError(f"recording {path} is incomplete: it has no end marker (the file was cut short, or its "
                         "run did not finish)" if complete else f"{path} holds no etmpc episodes")
    if len(complete) != end:
        raise EtmpcError(f"recording {path} is incomplete: {len(complete)} of its {end} episodes can be read")
    return complete


@dataclass(frozen=True)
class ReplayedEpisode:
    domain: str
    policy: str
    episode: int
    repeat: int
    seed: int
    objective_sense: str
    objective: float
    control_objective: float
    recomputes: int
    steps: int
    prediction_error_mean: float
    prediction_error_max: float
    prediction_error_at_recompute: float  # mean error at the steps where the policy chose to recompute


def replay_summary(path: str | Path) -> list[ReplayedEpisode]:
    """Each recorded episode's figures, with the live run's formulas (``etmpc.evaluate.scores``)."""
    out = []
    for root, data in read_recording(path).items():
        identity = data["identity"]
        _, rewards = data["reward"]
        _, recompute = data["recompute"]
        _, forced = data.get("forced", (None, np.zeros_like(recompute)))
        steps_err, errors = data.get("prediction_error", (np.zeros(0, int), np.zeros(0)))
        recomputes = int(recompute.sum())
        # The same expressions as Trajectory.policy_return and evaluate.scores, on the same floats.
        ret = float(rewards.sum() - identity["recompute_price"] * recomputes)
        control = float(rewards.sum())
        objective, control = (ret, control) if identity["objective_sense"] == "max" else (-ret, -control)
        chosen = np.flatnonzero((recompute > 0) & (forced == 0))
        at_recompute = errors[np.isin(steps_err, chosen)]
        out.append(ReplayedEpisode(
            domain=identity["domain"], policy=identity["policy"], episode=int(identity["episode"]),
            repeat=int(identity["repeat"]), seed=int(identity["seed"]), objective_sense=identity["objective_sense"],
            objective=objective, control_objective=control,
            recomputes=recomputes, steps=len(rewards),
            prediction_error_mean=_mean(errors),
            prediction_error_max=float(errors.max()) if len(errors) else float("nan"),
            prediction_error_at_recompute=_mean(at_recompute),
        ))
    out.sort(key=lambda r: (r.domain, r.policy, r.episode, r.repeat))
    return out


def _mean(values) -> float:
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else float("nan")


def _sense(group) -> str:
    return group[0].objective_sense


def format_replay(episodes: list[ReplayedEpisode], per_episode: bool = False) -> str:
    lines = []
    groups: dict[tuple[str, str], list[ReplayedEpisode]] = {}
    for e in episodes:
        groups.setdefault((e.domain, e.policy), []).append(e)
    labels = [f"  episode {e.episode} repeat {e.repeat}" for e in episodes] if per_episode else []
    width = max([16] + [len(p) + 2 for _, p in groups] + [len(label) + 2 for label in labels])
    head = (f"{'policy':<{width}}{'episodes':>9}{'objective':>12}{'control':>11}{'recomputes':>12}"
            f"{'pred.err mean':>15}{'max':>10}{'at recompute':>14}")
    current = None
    for (domain, policy), group in groups.items():
        if domain != current:
            lines += [f"{domain}: objective ({'higher' if _sense(group) == 'max' else 'lower'}"
                      " is better); prediction error ‖W (x − x̂)‖ against the plan in force", head, "-" * len(head)]
            current = domain
        for e in [None] + (group if per_episode else []):  # the policy's line, then its episodes
            chosen = group if e is None else [e]
            label = policy if e is None else f"  episode {e.episode} repeat {e.repeat}"
            mean = lambda attr: _mean([getattr(x, attr) for x in chosen])  # noqa: E731
            top = max((x.prediction_error_max for x in chosen if np.isfinite(x.prediction_error_max)), default=float("nan"))
            lines.append(f"{label:<{width}}{len(chosen):>9}{mean('objective'):>12.5f}{mean('control_objective'):>11.5f}"
                         f"{mean('recomputes'):>12.2f}{mean('prediction_error_mean'):>15.4f}{top:>10.4f}"
                         f"{mean('prediction_error_at_recompute'):>14.4f}")
    return "\n".join(lines)
