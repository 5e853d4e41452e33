"""One interface for every learner (in the manner of Stable-Baselines3's ``BaseAlgorithm``): GPOMDP,
DPI, the self-trigger and PPO are each a :class:`Learner`, and :func:`etmpc.learning.runner.run`
drives any of them the same way: seeds, checkpoints and resume, validation selection, cost.

A learner is one class::

    class MyLearner(Learner):
        name = "mine"                 # --algorithm mine; registered by defining the class
        Settings = MySettings         # a frozen dataclass that checks its ranges in __post_init__
        policy_kind = "rl"            # the evaluator's prefix for policy(): rl, self or sb3

        def setup(self): ...          # start afresh (self.key, self.seeds, self.out, self.pool are set)
        def milestones(self): ...     # the budget's points where the run is saved: [..., budget]
        def learn(self, budget, callback): ...   # train until `budget` (cumulative); callback(n): n units done
        def candidates(self): ...     # {name: policy spec or JSON} chosen among on validation episodes
        def choose(self, scores): ... # keep the best (the runner scored them), write the answer
        def policy(self): ...         # the run's answer as a spec etmpc evaluate scores
        def state(self): ...          # everything resume needs, JSON (None: not resumable)
        def load_state(self, state): ...

and nothing else: defining it registers it in :data:`LEARNERS` (``etmpc train --algorithm mine``,
:func:`etmpc.learning.runner.run`, ``reproduce`` and, with :attr:`Learner.shipped`, the leaderboard
find it there). Its settings come from a YAML or JSON file of field names (:func:`load_settings`). To be
resumed only as the run it was, it also says what ``out`` holds: ``saved_state()`` (each field checked as
it is read) and ``saved_identity(state)`` (the task and settings it was made with, see :meth:`Learner.identity`).
"""

from __future__ import annotations

import dataclasses
import importlib
import typing
from abc import ABC, abstractmethod
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Generic, Protocol, TypeVar, overload

from etmpc.common.documents import loads, yaml_loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign, strict
from etmpc.loop.records import EpisodeSink

if TYPE_CHECKING:
    from etmpc.systems import SystemKey

LEARNERS: dict[str, type[Learner]] = {}  # name -> class, filled as classes are defined
BUILT_IN = {
    "gpomdp": "etmpc.learning.phased",
    "dpi": "etmpc.learning.phased",
    "self": "etmpc.learning.selftrigger",
    "ppo": "etmpc.learning.ppo",
}  # the modules that define the built-in learners


class Pool(Protocol):
    """What a learner asks of the worker backend (:func:`etmpc.evaluation.backends.make_backend`'s): ``fn`` of each
    job, in job order, ``on_result(job)`` called as each ends."""

    def map(self, fn: Callable[[Any], Any], jobs: list, on_result: Callable[[Any], object] | None = None) -> list: ...


T = TypeVar("T")


class SetByRunner(Generic[T]):
    """An attribute of a learner that :func:`etmpc.learning.runner.run` sets before it calls the learner (the
    task, the seeds, the run's directory, the worker backend): read before it is set, it is an error that says
    so, not a None met later."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, learner: None, owner: type | None = None) -> SetByRunner[T]: ...

    @overload
    def __get__(self, learner: Learner, owner: type | None = None) -> T: ...

    def __get__(self, learner: Learner | None, owner: type | None = None) -> T | SetByRunner[T]:
        if learner is None:
            return self  # read on the class (help(), introspection): the descriptor itself
        value = learner.__dict__.get(self.name)
        if value is None:
            raise EtmpcError(f"{learner.name}: its {self.name} is not set: run it with etmpc.learning.runner.run")
        return value

    def __set__(self, learner: Learner, value: T | None) -> None:
        learner.__dict__[self.name] = value  # None: released (the backend, once the run ends)


class Learner(ABC):
    """A learner of a policy; see the module docstring. The runner sets :attr:`key` (the task at its
    price), :attr:`seeds`, :attr:`out` (the run's directory), :attr:`pool` (the worker backend),
    :attr:`say` and :attr:`tick` (the progress bar), and what its caller draws with, or None:
    :attr:`recorder` (opens a recording at a path: :class:`etmpc.views.recording.Recorder`) and
    :attr:`curve_png` (draws the learning curve: :func:`etmpc.views.curves.write_curve_png`), before it
    calls :meth:`setup` or :meth:`load_state`."""

    name: ClassVar[str] = ""
    Settings: ClassVar[type]
    policy_kind: ClassVar[str] = "rl"
    seeding: ClassVar[str] = "many"  # "many": any seeds, trained in lockstep; "one": exactly one; "none": no seed
    resumes_exactly: ClassVar[bool] = False  # a resumed run ends bit for bit like an uninterrupted one
    shipped: ClassVar[tuple[str, str, str] | None] = None  # leaderboard entry: (name, file in policies/<task>/, what it is)
    unit: ClassVar[str] = "episodes"  # what the budget counts
    # True: it trains only on tasks whose decisions are keep or solve (the runner refuses a task with
    # compute levels, keep, one SQP iteration or a full solve, before any work)
    keep_or_solve_only: ClassVar[bool] = False
    key: SetByRunner[SystemKey] = SetByRunner()  # the task at its price and with its options
    seeds: SetByRunner[tuple[int, ...]] = SetByRunner()
    out: SetByRunner[Path] = SetByRunner()  # the run's directory
    pool: SetByRunner[Pool] = SetByRunner()  # the worker backend, while the run goes on

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("name"):
            LEARNERS[cls.name] = cls

    def __init__(self, settings=None):
        self.settings = self.Settings() if settings is None else settings
        if not isinstance(self.settings, self.Settings):
            raise EtmpcError(f"{self.name}: settings must be {self.Settings.__name__}, got {type(self.settings).__name__}")
        self.workers = 1  # the run's worker processes (the runner sets it)
        self.tick: Callable[[int], None] = lambda n: None
        self.say: Callable[[str], None] = lambda line: None
        self.recorder: Callable[[Path], EpisodeSink] | None = None
        self.curve_png: Callable[[Path, dict, int], None] | None = None

    # What the runner calls, in this order.

    def check(self) -> None:
        """Checks before any work (a bad test set, a budget out of range); the run's directory too."""
        refuse_foreign(self.out, self.owns, f"{self.name} training run")

    def owns(self, name: str) -> bool:
        """Whether ``name`` in the run's directory is one of this learner's files."""
        return False

    def has_saved(self) -> bool:
        """Whether :attr:`out` holds a run's saved state (checked before it is read)."""
        return self.saved_state() is not None

    def saved_state(self) -> dict | None:
        """The state a run in :attr:`out` saved (None: none), for resume, each field checked as it is read
        (a folder handed to ``--resume`` is data: :mod:`etmpc.learning.resume`)."""
        return None

    def identity(self) -> dict:
        """The run asked for, as a saved state keeps it: ``{"task": str(self.key)`` (the task, its price and
        options), ``"settings":`` the settings as JSON``}``. A run in :attr:`out` is resumed only if its
        :meth:`saved_identity` is this (:func:`etmpc.learning.resume.same_run`)."""
        return {"task": str(self.key), "settings": strict(dataclasses.asdict(self.settings))}

    def saved_identity(self, state: dict) -> tuple[str, dict] | None:
        """The file :meth:`saved_state` read ``state`` from, and the :meth:`identity` of the run that saved it;
        None: the state keeps none, and the run is resumed unchecked (a learner of etmpc's keeps one)."""
        return None

    def default_seeds(self) -> tuple[int, ...]:
        """The seeds of a run given none."""
        return (0,)

    def work(self) -> int:
        """Units of work in all, for the progress bar (:attr:`tick` counts them as they are done)."""
        return self.milestones()[-1]

    def work_done(self) -> int:
        """Units of work a resumed run had done."""
        return self.done

    @abstractmethod
    def setup(self) -> None: ...

    @abstractmethod
    def milestones(self) -> list[int]: ...

    @property
    def done(self) -> int:
        """How much of the budget is done."""
        return 0

    @abstractmethod
    def learn(self, budget: int, callback: Callable[[int], None]) -> None: ...

    def save(self) -> None:
        """Write the run's files and state (after :meth:`setup`, each :meth:`learn` and :meth:`choose`)."""

    def report(self) -> str | None:
        """A line for the log after each milestone (None: none)."""
        return None

    @property
    def chosen(self) -> bool:
        """Whether :meth:`choose` has run (a resumed run that had chosen does not again)."""
        return False

    def validation_episodes(self) -> int:
        return getattr(self.settings, "validation_episodes")

    @abstractmethod
    def candidates(self) -> dict[str, Any]: ...

    def scores(self, validate: Callable[[list], list[float]]) -> list[float]:
        """The candidates' validation scores: ``validate(policies)`` (the runner's), or ones already kept."""
        return validate(list(self.candidates().values()))

    @abstractmethod
    def choose(self, scores: list[float]) -> None: ...

    @abstractmethod
    def policy(self) -> str: ...

    def state(self) -> dict | None:
        return None

    def load_state(self, state: dict) -> None:
        raise EtmpcError(f"{self.name} cannot resume a run")

    def close(self) -> None:
        """Release what :meth:`setup` made (environments, processes)."""

    def simulated_steps(self) -> int | None:
        """Environment steps the run simulated so far (None: not counted)."""
        return None


def check_decisions(learner: Learner | type[Learner], task: str) -> None:
    """Refuse, in one line, a learner that trains only keep-or-solve policies on a task with compute levels."""
    from etmpc.systems import has_levels

    if learner.keep_or_solve_only and has_levels(task):
        raise EtmpcError(
            f"{learner.name} needs a task whose decisions are keep or solve; task {task}'s are keep, one SQP "
            "iteration or a full solve (compute levels): train it with --algorithm dpi"
        )


def learners() -> dict[str, type[Learner]]:
    """Every registered learner, the built-in ones first (gpomdp, dpi, self, ppo)."""
    for module in dict.fromkeys(BUILT_IN.values()):
        importlib.import_module(module)
    return {**{name: LEARNERS[name] for name in BUILT_IN}, **LEARNERS}


def learner_class(name: str) -> type[Learner]:
    found = learners()
    if name not in found:
        raise EtmpcError(f"unknown algorithm {name!r}; valid: {', '.join(found)}")
    return found[name]


def shipped() -> list[tuple[str, str, str, str]]:
    """The leaderboard's shipped learners: ``(entry, file in policies/<task>/, spec prefix, what it is)``."""
    return [(s[0], s[1], f"{cls.policy_kind}:", s[2]) for cls in learners().values() if (s := cls.shipped) is not None]


def settings_from(cls: type, values: dict, where: str, base=None):
    """``cls`` (a settings dataclass) from a mapping of its field names, over ``base`` (default: its
    defaults). Lists become tuples where the field is a tuple; an unknown name is an error."""
    if not isinstance(values, dict):
        raise EtmpcError(f"{where}: settings must map names to values, got {type(values).__name__}")
    names = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise EtmpcError(f"{where}: unknown setting {unknown[0]!r}; known: {', '.join(names)}")
    hints = typing.get_type_hints(cls)
    converted = {}
    for name, value in values.items():
        if isinstance(value, list) and "tuple" in str(hints.get(name)):
            value = tuple(value)
        elif isinstance(value, dict) and dataclasses.is_dataclass(hints.get(name)):
            value = settings_from(hints[name], value, f"{where}: {name}")
        converted[name] = value
    try:
        return dataclasses.replace(cls() if base is None else base, **converted)
    except (EtmpcError, ValueError, TypeError) as exc:
        raise EtmpcError(f"{where}: {exc}") from None


def load_settings(learner: type[Learner], path: str | Path | None, task: str | None = None):
    """``learner``'s settings from a YAML or JSON file of field names (None: the defaults). A learner
    with its own file format defines a classmethod ``read_settings(path, task)``."""
    own = learner.__dict__.get("read_settings")
    if own is not None:
        return own.__get__(None, learner)(path, task)
    if path is None:
        return learner.Settings()
    path = Path(path)
    try:
        text = path.read_text()
        document = loads(text) if path.suffix == ".json" else yaml_loads(text)
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path}: cannot read it ({' '.join(str(exc).split())})") from None
    return settings_from(learner.Settings, document or {}, str(path))
