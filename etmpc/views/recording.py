"""The writer of Rerun recordings of episodes: :class:`Recorder`. What a file holds, entity by entity, is
:mod:`etmpc.views.schema`'s; reading a file back is :mod:`etmpc.views.replay`'s."""

from __future__ import annotations

import threading
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from etmpc.views import blueprint as look
from etmpc.common.sense import sign as sense_sign
from etmpc.loop import computation_cost
from etmpc.loop.records import EpisodeRecord
from etmpc.views.layout import _about, _fan, _slots, _solve_series, _timeline
from etmpc.views.decisions import log_decisions
from etmpc.views.solves import solve_log
from etmpc.views.schema import APPLICATION_ID, END_MARKER, episode_root
from etmpc.views.sinks import Destinations, is_url
from etmpc.views.space import log_space

if TYPE_CHECKING:  # imported for the run by a thread of the Recorder's (it takes a second or two)
    import rerun


class Recorder:
    """Writes episodes into one ``.rrd`` file, and/or streams them to a Rerun viewer: ``connect=URL`` (one
    running, ``rerun+http://HOST:PORT/proxy``; a URL given as ``path`` is taken so too) or ``spawn=True`` (one
    started for it): :class:`etmpc.views.sinks.Destinations`, each checked here. The file appears under its
    name only once it is complete: it is written beside it and renamed on ``close``, after the blueprint
    (which needs every episode) and an end marker.

    Rerun (and the pandas that pyarrow loads on its first numpy array) takes a second or two to
    import: a thread started here imports it while the caller plays its episodes, and the file is
    opened when the first episode comes."""

    def __init__(self, path: str | Path | None = None, *, connect: str | None = None, spawn: bool = False):
        if is_url(path):  # a viewer's URL where a file's path goes (--record rerun+http://...)
            path, connect = None, path
        self._imported: list = []
        self._importer = threading.Thread(target=_import_rerun, args=(self._imported,), daemon=True)
        self._importer.start()
        self.destinations = Destinations(path, connect, spawn, rerun=self._rerun)  # each checked: before any work
        self.path = self.destinations.path
        self._rr: ModuleType | None = None  # the rerun module, once opened
        self._stream: rerun.RecordingStream | None = None
        self._policy_parts: dict[tuple[str, str], str] = {}
        self._styles: dict = {}
        self._indexes: dict = {}
        self.layouts: list[look.EpisodeLayout] = []
        self.episodes = 0

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(keep=exc_type is None)

    def _rerun(self) -> ModuleType:
        """The ``rerun`` module, once the thread has imported it."""
        self._importer.join()
        if isinstance(self._imported[0], BaseException):
            raise self._imported[0]
        return self._imported[0]

    def _open(self) -> tuple[ModuleType, rerun.RecordingStream]:
        if self._rr is None or self._stream is None:
            rr = self._rerun()
            self._rr = rr
            self._stream = rr.RecordingStream(APPLICATION_ID)
            self.destinations.attach(rr, self._stream)
        return self._rr, self._stream

    def close(self, keep: bool = True) -> None:
        try:
            if keep:
                rr, stream = self._open()
                if self.layouts:
                    stream.send_blueprint(look.blueprint(self.layouts))
                # The end marker: a reader that does not find it knows the file was cut short.
                stream.log(END_MARKER, rr.AnyValues(episodes=self.episodes), static=True)
            if self._stream is not None:
                self._stream.flush()
                self._stream.disconnect()
        except (OSError, RuntimeError) as exc:  # RuntimeError: Rerun's writer gave up (a full disk, a viewer gone)
            keep = False
            raise self.destinations.failed(exc) from None
        except BaseException:
            keep = False
            raise
        finally:
            self.destinations.finish(keep)

    def _policy_part(self, domain: str, policy: str) -> tuple[str, str]:
        """``(label, entity path part)`` of a policy spec: two specs with the same label stay apart."""
        key = (domain, policy)
        if key not in self._policy_parts:
            base = look.policy_label(policy)
            taken = {name for (d, _), name in self._policy_parts.items() if d == domain}
            name, i = base, 2
            while name in taken:
                name, i = f"{base} ({i})", i + 1
            self._policy_parts[key] = name
        name = self._policy_parts[key]
        rr, _ = self._open()  # open already: log_episode opened it
        return name, rr.escape_entity_path_part(name.replace("/", "_"))  # one path part

    def _style(self, kind: str, **fields):
        """A static ``SeriesLines`` or ``SeriesPoints``, built once per look (they repeat from one
        episode to the next, and building one costs more than logging it)."""
        key = (kind, repr(sorted(fields.items())))
        if key not in self._styles:
            self._styles[key] = getattr(self._rr, kind)(**fields)
        return self._styles[key]

    def _steps(self, count: int, dt: float) -> list:
        """The index of steps ``0..count-1`` (kept: most series share one)."""
        key = (count, dt)
        if key not in self._indexes:
            self._indexes[key] = _timeline(np.arange(count), dt)
        return self._indexes[key]

    def log_episode(self, record: EpisodeRecord, frames: Iterable[np.ndarray] | None = None) -> str:
        """Log one episode (and, optionally, rendered frames, one per state); returns its root path."""
        rr, stream = self._open()
        identity = record.identity
        task = look.task_part(identity["domain"], identity["task"])
        name, part = self._policy_part(task, identity["policy"])
        root = episode_root(identity, part)
        dt = identity["control_interval_s"]
        n = record.steps
        written: list[str] = []

        def series(path, index, values, names, kind="SeriesLines", **style):
            stream.send_columns(f"{root}/{path}", index, rr.Scalars.columns(scalars=np.asarray(values, float)))
            stream.log(f"{root}/{path}", self._style(kind, names=list(names), **style), static=True)
            written.append(path)

        stream.log(f"{root}/identity", rr.AnyValues(**identity), static=True)

        # What happened. Entities drawn in one view are drawn in the order of their paths, so
        # ``realised/…`` comes over ``plan/…`` and ``forecast/…``.
        realised = dict(colors=[look.REALISED], widths=[look.REALISED_WIDTH])
        # A sensor that is not exact: its readings and the estimate beside the truth (a record keeps both or neither).
        estimates = record.estimates
        measurements = record.measurements
        for j, s in enumerate(record.state_names):
            if estimates is not None and measurements is not None:
                series(
                    f"realised/state/{s}",
                    self._steps(n + 1, dt),
                    np.column_stack([record.states[:, j], estimates[:, j], measurements[:, j]]),
                    [f"what happened [{look.unit(s)}]", f"estimated [{look.unit(s)}]", f"measured [{look.unit(s)}]"],
                    colors=[look.REALISED, look.ESTIMATED, look.MEASURED],
                    widths=[look.REALISED_WIDTH, 1.5, 1.0],
                )
                continue
            series(
                f"realised/state/{s}",
                self._steps(n + 1, dt),
                record.states[:, j],
                [f"what happened [{look.unit(s)}]"],
                **realised,
            )
        for j, u in enumerate(record.input_names):
            what = f"[{look.unit(u)}]"
            if record.input_bounds:  # the bounds as two more series of the input, grey
                lo, hi = (float(b[j]) for b in record.input_bounds)
                values = np.column_stack([record.applied[:, j], np.full(n, lo), np.full(n, hi)])
                series(
                    f"realised/input/{u}",
                    self._steps(n, dt),
                    values,
                    [f"applied {what}", f"lower bound {what}", f"upper bound {what}"],
                    colors=[look.REALISED, look.BOUND, look.BOUND],
                    widths=[look.REALISED_WIDTH, 1.0, 1.0],
                )
            else:
                series(f"realised/input/{u}", self._steps(n, dt), record.applied[:, j], [f"applied {what}"], **realised)
            series(f"correction/{u}", self._steps(n, dt), record.correction[:, j], [f"LQR correction {what}"], **realised)
        forecasts: dict[str, str] = {}  # signal -> its forecast, for the signals the plans forecast
        for f in record.plans[0][3] if record.plans else {}:
            signal = look.signal_of_forecast(f, record.signals)
            if signal is not None:
                forecasts[signal] = f
        for s, values in record.signals.items():
            series(
                f"realised/signal/{s}",
                self._steps(n, dt),
                values[:n],
                [f"true [{look.unit(s)}]" if s in forecasts else look.label(s)],
                **realised,
            )

        # The plans, as time series from the step each was made.
        if record.plans:
            made = np.array([k for k, *_ in record.plans])
            slots, n_slots = _slots(made, max(p[1].shape[0] for p in record.plans))
            colours = look.plan_colours(made, n)
            # Every slot drawn: the viewer shows only the first 20 series of an entity unless told.
            plan_style = lambda what: self._style(  # noqa: E731
                "SeriesLines", names=[what] * n_slots, widths=[look.PLAN_WIDTH] * n_slots, visible_series=[True] * n_slots
            )
            fans = [
                (f"plan/state/{s}", np.stack([p[1][:, j] for p in record.plans]), n, f"each plan [{look.unit(s)}]")
                for j, s in enumerate(record.state_names)
            ]
            fans += [
                (f"plan/input/{u}", np.stack([p[2][:, j] for p in record.plans]), n - 1, f"each plan [{look.unit(u)}]")
                for j, u in enumerate(record.input_names)
            ]
            fans += [
                (f"forecast/{s}", np.stack([p[3][f] for p in record.plans]), n - 1, f"each forecast [{look.unit(s)}]")
                for s, f in forecasts.items()
            ]
            for path, values, last, what in fans:
                stream.send_columns(
                    f"{root}/{path}", self._steps(last + 1, dt), _fan(made, slots, n_slots, values, last, colours)
                )
                stream.log(f"{root}/{path}", plan_style(what), static=True)
                written.append(path)
        written += log_space(rr, stream, root, record, dt)  # a system with a Space: its 3-D view (etmpc.views.space)

        # The decisions: each step's, the recomputes by kind and what each was told, the error and the threshold.
        written += log_decisions(rr, stream, root, record, series, self._steps(n, dt))

        if record.timed:  # time in the loop: each step's recompute, the plan in force, each solve's start and arrival
            for path, steps, values, names, kind, style in _solve_series(record):
                series(path, _timeline(steps, dt), values, names, kind=kind, **style)
            steps, text, levels = solve_log(record, bool(identity.get("compute_levels")))
            stream.send_columns(f"{root}/events/solves", _timeline(steps, dt), rr.TextLog.columns(text=text, level=levels))
            written.append("events/solves")

        # The objective: each recompute priced by its work (1 per solve, or its SQP iterations).
        sign = sense_sign(identity["objective_sense"])
        running = sign * np.cumsum(record.rewards - computation_cost(record.work, identity["recompute_price"]))
        series("objective/reward", self._steps(n, dt), record.rewards, ["reward"], **realised)
        series(
            "objective/running",
            self._steps(n, dt),
            running,
            [f"running {'profit (higher' if sign > 0 else 'cost (lower'} is better)"],
            **realised,
        )

        if frames is not None:
            for i, frame in enumerate(frames):
                stream.set_time("step", sequence=i)
                stream.set_time("time", duration=i * dt)
                stream.log(f"{root}/camera", rr.Image(frame).compress(jpeg_quality=85))
            written.append("camera")

        stream.log(
            f"{root}/about",
            rr.TextDocument(_about(name, record, running[-1] if n else 0.0), media_type="text/markdown"),
            static=True,
        )
        y_ranges = {}
        for s in forecasts:
            lo, hi = float(np.min(record.signals[s][:n])), float(np.max(record.signals[s][:n]))
            pad = 0.1 * (hi - lo) or 0.1 * abs(hi) or 1.0
            y_ranges[s] = (lo - pad, hi + pad)
        self.layouts.append(
            look.EpisodeLayout(
                root=root,
                domain=task,
                policy=name,
                episode=int(identity["episode"]),
                repeat=int(identity["repeat"]),
                steps=n,
                control_interval_s=dt,
                states=record.state_names,
                inputs=record.input_names,
                signals=tuple(s for s in record.signals if s not in forecasts),
                forecast_signals=tuple(s for s in record.signals if s in forecasts),
                entities=frozenset(written),
                y_ranges=y_ranges,
                objective_unit=look.objective_unit(identity["domain"], identity["task"]),
            )
        )
        self.episodes += 1
        return root


def _import_rerun(out: list) -> None:
    """Import Rerun and warm pyarrow up (it imports pandas on its first numpy array); ``out``
    receives the module, or the exception."""
    try:
        import pyarrow as pa
        import rerun as rr
        import rerun.blueprint  # noqa: F401

        pa.array(np.zeros(1, dtype=np.int64))
        out.append(rr)
    except BaseException as exc:  # handed to the thread that needs Rerun
        out.append(exc)
