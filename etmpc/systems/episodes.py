"""What the tasks of every domain share: one owner of randomness, and stored episodes replayed exactly."""

from __future__ import annotations

import collections
import math
import numbers
from typing import Any

import numpy as np
import numpy.typing as npt
from dm_control.rl import control
from dm_env import specs

from etmpc.common.declared import setting

Random = np.random.Generator | np.random.RandomState | int | None
#: A stored episode's bound on a Gaussian's draw, in its standard deviations (beyond it: probability 1.5e-23 a draw).
GAUSSIAN_BOUND_STD = 10.0
#: The largest factor a disturbance may be scaled by when it is played (``disturbances.*_scale``), and the most
#: events a second a rate may draw (at most 1,000 per 100-step episode of 0.1 s: the draws stay small).
MAX_SCALE, MAX_EVENTS_PER_S = 100.0, 100.0


def scale_setting(what: str) -> Any:
    """A factor on every disturbance of a kind as it is played (a stored episode's too), as an option."""
    return setting(1.0, low=0, high=MAX_SCALE, why=f"every {what} played, times this: acts on a stored test set too")


def drawn_setting(default: Any, high: float, why: str, unit: str = "", pair: bool = False) -> Any:
    """A setting of how episodes are drawn, from 0 to ``high`` (a probability, a rate, a size; with ``pair``, a
    range ``(low, high)`` drawn uniformly), as an option: ``etmpc testset --option ...`` draws a test set with it,
    and a rollout redraws a future with it."""
    return setting(default, low=0, high=high, unit=unit, draws=True, pair=pair, why=why)


def jumps_setting(default: float, interval_s: float, what: str) -> Any:
    """The jumps a second of ``what`` (a target, a reference), as an option drawn with: at most one an interval
    of ``interval_s`` (the episode draws a jump per interval with probability ``jumps a second * interval_s``)."""
    return drawn_setting(default, 1 / interval_s, f"{what}'s jumps a second: at most one an interval", unit="1/s")


def generator(random: Random) -> np.random.Generator:
    """The task's generator from what ``dm_control.suite`` tasks accept as ``random``.

    A ``Generator`` is used as given; an int seeds a new one; ``None`` draws fresh entropy; a
    ``RandomState`` (the suite's own type) seeds a new ``Generator`` from four of its draws, so
    the same ``RandomState`` state gives the same episodes.
    """
    if isinstance(random, np.random.Generator):
        return random
    if isinstance(random, np.random.RandomState):
        return np.random.default_rng(random.randint(0, 2**32, size=4, dtype=np.uint64))
    if random is None or (isinstance(random, numbers.Integral) and not isinstance(random, bool)):
        if random is not None and random < 0:
            raise ValueError(f"random seed must be non-negative, got {random}")
        return np.random.default_rng(random)
    raise TypeError(f"random must be an int seed, a numpy Generator or RandomState, or None; got {type(random).__name__}")


def jump_process(rng: np.random.Generator, current: npt.ArrayLike, steps: int, probability: float, draw) -> np.ndarray:
    """A signal that holds its value and, at each of ``steps`` intervals, jumps with ``probability``
    to a new value ``draw(rng)``: the intervals after one whose value is ``current``, shape
    ``(steps, *current.shape)``. Draws the jumps first, then the new values in order, so a future
    redrawn from an interval on (a rollout's) uses the generator as the episode's own draw did."""
    jumps = rng.random(steps) < probability
    value = np.asarray(current, dtype=float)
    values = np.empty((steps, *value.shape))
    new = [draw(rng) for _ in range(int(jumps.sum()))]
    for j in range(steps):
        if jumps[j]:
            value = np.asarray(new.pop(0), dtype=float)
        values[j] = value
    return values


def outside(values: Any, low: Any, high: Any) -> str | None:
    """What is outside ``[low, high]`` in ``values`` (bounds broadcast against it; NaN is outside), or None:
    the first such value, where it is and the range, in words."""
    values = np.asarray(values)
    low, high = np.broadcast_to(low, values.shape), np.broadcast_to(high, values.shape)
    inside = (values >= low) & (values <= high)
    if inside.all():
        return None
    at = np.unravel_index(np.argmin(inside), values.shape)  # the first value outside
    where = f" at {list(map(int, at))}" if values.ndim else ""
    return f"{values[at].item()!r}{where} is outside the task's range [{low[at].item()!r}, {high[at].item()!r}]"


def steps_for(time_limit: float, interval_s: float) -> int:
    """The number of control intervals in ``time_limit`` seconds; a whole, positive number is required
    (an episode's exogenous signals are drawn in advance, so it cannot be open-ended)."""
    try:
        seconds = float(time_limit)
    except (TypeError, ValueError):
        raise TypeError(f"time_limit must be a number of seconds, got {time_limit!r}") from None
    steps = round(seconds / interval_s) if math.isfinite(seconds) else 0
    if steps < 1 or not math.isclose(steps * interval_s, seconds, rel_tol=1e-9, abs_tol=1e-12):
        raise ValueError(f"time_limit must be a positive whole number of {interval_s:g} s control intervals, got {time_limit!r}")
    return steps


def environment_kwargs_for(time_limit_s: float, interval_s: float, environment_kwargs: dict | None) -> dict:
    """``control.Environment``'s arguments: the task's time limit and interval, then the user's others.

    The interval and the episode's length belong to the task (its signals are drawn for them):
    ``time_limit`` goes in ``task_kwargs``, and ``control_timestep`` cannot be changed.
    """
    user = dict(environment_kwargs or {})
    if "time_limit" in user:
        raise ValueError("pass time_limit in task_kwargs, not environment_kwargs: the episode is drawn for it")
    if "control_timestep" in user and user["control_timestep"] != interval_s:
        raise ValueError(f"control_timestep is the task's {interval_s:g} s and cannot be changed")
    return dict(time_limit=time_limit_s, control_timestep=interval_s) | user


def build_environment(physics, task, steps: int, interval_s: float, environment_kwargs: dict | None = None):
    """The :class:`Environment` of ``task`` on ``physics``: ``steps`` intervals of ``interval_s``, then the
    user's other ``environment_kwargs`` (:func:`environment_kwargs_for`)."""
    return Environment(physics, task, **environment_kwargs_for(steps * interval_s, interval_s, environment_kwargs))


def add_task(
    suite,
    name: str,
    make_environment,
    steps: int,
    interval_s: float,
    summary: str,
    tags: tuple[str, ...] = ("benchmarking",),
    episode: type | None = None,
):
    """Add task ``name`` to ``suite`` (a ``containers.TaggedTasks``) as ``dm_control.suite``'s factories
    are: ``name(time_limit=steps * interval_s, random=None, environment_kwargs=None, **settings)`` returns
    ``make_environment(random=..., steps=..., environment_kwargs=..., **settings)``, ``settings`` being
    the task's own (the cart pendulum's ``plant``). ``summary`` is the factory's docstring.

    The one place a task declares its episode: ``steps`` control intervals of ``interval_s``, drawn as
    ``episode`` (its ``Episode`` class). The factory carries them (``.steps``, ``.interval_s``,
    ``.episode``), and the task's system reads them from it (:class:`~etmpc.systems.base.SystemBase`)."""

    def factory(time_limit: float = steps * interval_s, random: Any = None, environment_kwargs: dict | None = None, **settings):
        return make_environment(
            random=random, steps=steps_for(time_limit, interval_s), environment_kwargs=environment_kwargs, **settings
        )

    factory.__name__ = factory.__qualname__ = name
    factory.__doc__ = summary
    # mypy does not model attributes set on a function object (a dm-control suite's entries are functions)
    factory.steps = steps  # type: ignore[attr-defined]
    factory.interval_s = interval_s  # type: ignore[attr-defined]
    factory.episode = episode  # type: ignore[attr-defined]
    return suite.add(*tags)(factory)


class Environment(control.Environment):
    """``control.Environment`` whose ``flat_observation`` spec is right for tasks that state their spec.

    dm-control infers a flat spec only for tasks without ``observation_spec``; ours state theirs,
    so the flat spec (one float64 vector under ``"observations"``) is made from it here.
    """

    def observation_spec(self):
        spec = super().observation_spec()
        if not self._flat_observation:
            return spec
        size = sum(int(np.prod(array.shape)) for array in spec.values())
        key = control.FLAT_OBSERVATION_KEY
        return collections.OrderedDict([(key, specs.Array((size,), np.float64, name=key))])


class EpisodeTask(control.Task):
    """A dm-control task whose episodes are drawn in advance, whole.

    Randomness has one owner: the task's ``random`` generator draws each episode on reset
    (:meth:`draw_episode`), unless :meth:`use_episode` has queued a stored one (a test-set episode),
    which is then replayed exactly. ``random`` is what the suite's tasks accept (see
    :func:`generator`).
    """

    def __init__(self, random: Random = None):
        self._random = generator(random)
        self._queued: Any = None
        self._episode: Any = None
        self._visualize_reward = False
        # True after a step in which the task put the plant back (a fallen pole caught and re-erected):
        # the plan no longer applies, and the control loop solves a new one at the next step.
        self.restarted = False

    @property
    def random(self) -> np.random.Generator:
        return self._random

    @property
    def visualize_reward(self) -> bool:
        """Colour the rendered scene by the reward, as ``dm_control.suite`` tasks do."""
        return self._visualize_reward

    @visualize_reward.setter
    def visualize_reward(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise ValueError(f"visualize_reward must be a bool, got {type(value).__name__}")
        self._visualize_reward = value

    @property
    def episode(self) -> Any:
        """The episode being played (drawn or stored)."""
        return self._episode

    def use_episode(self, episode: Any) -> None:
        """Play ``episode`` at the next reset (``None``: draw from ``random`` again). Its lengths are checked
        (:meth:`check_episode`), not its values: an episode made by hand may start where no draw does (a pole
        at 1 rad, to see it fall); a test set's are checked against the task's ranges (:meth:`check_stored`)."""
        if episode is not None:
            self.check_episode(episode)
        self._queued = episode

    def next_episode(self) -> Any:
        """The queued episode, or a new one drawn from ``random``; becomes :attr:`episode`."""
        episode, self._queued = self._queued, None
        self._episode = episode if episode is not None else self.draw_episode(self._random)
        return self._episode

    def resume(self, episode: Any, step: int) -> None:
        """Continue ``episode`` from ``step`` (the next ``before_step`` applies step ``step``'s
        exogenous values): how a rollout puts the task back where a snapshot was taken, possibly
        with another future. The episode is not checked: it comes from this task or its sampler."""
        self._episode, self._step = episode, step

    def check_episode(self, episode: Any) -> None:
        """Raise ``ValueError`` if ``episode`` cannot be played by this task (its lengths: the task's own check)."""

    def episode_ranges(self) -> dict[str, tuple[Any, Any]]:
        """The closed range ``(low, high)`` of each field of an episode, by the names of ``Episode.arrays()``:
        the values the task's draws can give (``low`` and ``high`` broadcast against the field: a vector of
        bounds for a state's components). {} by default: a task that declares none has only its lengths
        checked. A task whose distribution has no bound (a Gaussian) declares one no draw reaches. Test sets
        are checked against them (:meth:`check_stored`)."""
        return {}

    def check_stored(self, episode: Any) -> None:
        """Raise ``ValueError`` unless ``episode``, read from a test set, is one this task plays: the task's
        :meth:`check_episode`, then every field within :meth:`episode_ranges`, the first one outside named. A
        test set is someone's file: a gust of 2**62 intervals, say, played into a traceback; outside its
        task's ranges it is no episode of the task, and it is refused before it is played (a test set's
        episodes all are, by ``TestSet.check_playable``)."""
        self.check_episode(episode)
        for name, (low, high) in self.episode_ranges().items():
            problem = outside(getattr(episode, name), low, high)
            if problem is not None:
                raise ValueError(f"{name}: {problem}")

    def get_termination(self, physics) -> float | None:
        """A non-finite state (``physics.state()``) ends the episode (discount 0); the control loop reports it."""
        return None if np.all(np.isfinite(physics.state())) else 0.0

    def draw_episode(self, random: np.random.Generator) -> Any:
        raise NotImplementedError
