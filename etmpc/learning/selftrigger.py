"""Training of the self-triggering policy (``etmpc train --algorithm self``, see :mod:`etmpc.policies.selftrigger`).

**Training** (:func:`train_self`) is one step of rollout policy improvement over a base schedule,
as :mod:`etmpc.learning.dpi` does for event triggering:

1. the base ``every:T`` is the best of ``bases`` on training-distribution episodes (as DPI chooses
   its first schedule);
2. on training-distribution episodes played by the base, at a few picked steps, a plan is solved and
   every candidate ``n`` scored: the mean return, over ``K`` futures sampled from what the
   controller knows (common random numbers), of keeping that plan ``n`` steps and then following
   the base, ``H`` steps past the longest candidate plus the truncation value (DPI's labeller,
   :class:`etmpc.learning.dpi.Labeller`, with this label);
3. the model is fitted to each labelled solve's best candidate by ridge-regularised cross-entropy,
   each solve weighted by how much the choice matters (best minus mean return), for each ridge of
   ``ridges``;
4. the policy kept is the best, on validation episodes of the training distribution, of these fits
   and of the base itself written as a self-trigger (a constant announcement ``T``), so what
   training returns is never worse than its base on those episodes. The test set is never seen.
"""

from __future__ import annotations

import types
import typing
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from etmpc.common import checks
from etmpc.common.sense import oriented
from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.learning.base import Learner
from etmpc.learning.config import SELECTION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.learning.resume import AGAIN, corrupt
from etmpc.learning.selftrigger_labels import (  # noqa: F401 (SELF_ENTROPY re-exported, as before the split)
    SELF_ENTROPY,
    fit,
    label_episode,
)
from etmpc.policies import Always, Every, parse_policy
from etmpc.policies.selftrigger import CANDIDATES, SelfTrigger, from_json
from etmpc.systems import SystemKey, system_key


@dataclass(frozen=True)
class SelfSettings:
    bases: tuple[str, ...] = ("always", "every:2", "every:3", "every:5", "every:8", "every:12", "every:20")
    selection_episodes: int = 20  # training-distribution episodes that choose the base
    episodes: int = 40  # labelled training episodes
    solves_per_episode: int = 8  # labelled solves per episode
    futures: int = 2  # K
    horizon: int = 10  # H: steps simulated past the longest candidate
    ridges: tuple[float, ...] = (1e-2, 1e-1, 1.0)
    validation_episodes: int = 20  # training-distribution episodes that choose among the fits and the base
    candidates: tuple[int, ...] = CANDIDATES

    def __post_init__(self):
        checks.typed(self, finite=True, most=checks.MAX_COUNT)
        for name in ("selection_episodes", "episodes", "solves_per_episode", "futures", "validation_episodes"):
            if getattr(self, name) < 1:
                raise EtmpcError(f"self-trigger training needs {name} >= 1, got {getattr(self, name)}")
        if self.horizon < 0 or not self.ridges or min(self.ridges) <= 0 or not self.bases:
            raise EtmpcError("self-trigger training needs horizon >= 0, ridges > 0 and at least one base")

    def to_json(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


class SelfLearner(Learner):
    """The self-trigger's training behind the learner interface: :meth:`setup` chooses the base,
    :meth:`learn` labels ``settings.episodes`` episodes and fits one model per ridge, the runner scores
    them and the base on validation episodes and :meth:`choose` writes the best. One pass, no seed
    (its draws are one fixed stream) and no checkpoint: a run that was stopped starts again."""

    name = "self"
    Settings = SelfSettings
    policy_kind = "self"
    seeding = "none"
    keep_or_solve_only = True  # it announces when to solve next

    def __init__(self, settings: SelfSettings | None = None, policy_file: Path | None = None):
        super().__init__(settings)
        self.policy_file = policy_file  # where the policy goes (default: OUT/selected.json)
        self._standalone = policy_file is not None  # train_self: a file, written over as before
        self.written: SelfTrigger | None = None  # the policy this invocation wrote
        self.finished = False  # the policy chosen and written, by this invocation or the run it resumed

    @property
    def selected_file(self) -> Path:
        """Where the policy goes: the file given, or the one :meth:`check` names in the run's directory."""
        if self.policy_file is None:
            raise EtmpcError("self: no policy file yet: check() names it in the run's directory")
        return self.policy_file

    def owns(self, name: str) -> bool:
        return name == "selected.json"

    def check(self) -> None:
        if self.policy_file is None:
            super().check()
            self.policy_file = self.out / "selected.json"
        self.system = self.key.make()
        sense = self.system.objective_sense
        self.better = lambda values: int(np.argmax(oriented(np.asarray(values, dtype=float), sense)))  # first of a tie
        self.candidate_lengths = tuple(c for c in self.settings.candidates if c <= self.system.horizon)
        if not self.candidate_lengths:
            raise EtmpcError(f"no candidate keep length fits the MPC horizon ({self.system.horizon} steps)")

    def saved_state(self) -> dict | None:
        """The finished run in :attr:`out`: its ``selected.json``, each field checked (:func:`read_run`)."""
        return read_run(self.selected_file) if not self._standalone and self.selected_file.exists() else None

    def identity(self) -> dict:
        return {"task": str(self.key), "settings": self.settings.to_json()}

    def saved_identity(self, state: dict) -> tuple[str, dict]:
        hyper = state["hyperparameters"]
        return str(self.policy_file), {"task": hyper["system"], "settings": {k: hyper[k] for k in self.settings.to_json()}}

    def load_state(self, state: dict) -> None:
        if state["domain"] != self.system.name or state["hyperparameters"]["recompute_price"] != self.system.recompute_price:
            raise corrupt(self.selected_file, f"its policy is not one of {self.key}'s")
        self.finished = True  # the run had finished

    @property
    def chosen(self) -> bool:
        return self.finished

    @property
    def done(self) -> int:
        return self.settings.episodes if self.finished or hasattr(self, "fits") else 0

    def milestones(self) -> list[int]:
        return [self.settings.episodes]

    def setup(self) -> None:
        settings, pool = self.settings, self.pool
        self.selection = mean_scores(pool, self.key, list(settings.bases), SELECTION_ENTROPY, settings.selection_episodes)
        self.base = settings.bases[int(self.better(self.selection))]
        self.say(
            f"self-trigger: base {self.base} (best of {len(settings.bases)} on {settings.selection_episodes} training episodes)"
        )

    def learn(self, budget: int, callback) -> None:
        settings = self.settings
        system = self.system
        candidates = self.candidate_lengths
        out = self.selected_file
        jobs = [(self.key, self.base, candidates, settings, i) for i in range(budget)]
        labelled = self.pool.map(_label_job, jobs, lambda job: callback(1))  # each labelled episode counted as it ends
        self.rows = [row for episode in labelled for row in episode]
        if not self.rows:
            raise EtmpcError("no solves were labelled; give more episodes")
        features = np.array([f for f, _ in self.rows])
        self.returns = np.array([q for _, q in self.rows])
        mean, scale = features.mean(axis=0), features.std(axis=0)
        scale = np.where(scale > 1e-12, scale, 1.0)
        self.fits = {}
        period = _period(self.base, system)
        if period in candidates:  # the base itself, as a self-trigger: what training must beat (first: it wins ties)
            self.fits[f"constant {period} (the base)"] = SelfTrigger.constant(
                str(out), system.name, candidates, period, mean.size
            )
        for r in settings.ridges:
            self.fits[f"ridge {r:g}"] = SelfTrigger(
                str(out), system.name, candidates, fit((features - mean) / scale, self.returns, r), mean, scale
            )

    def candidates(self) -> dict:
        return {name: policy.to_json() for name, policy in self.fits.items()}

    def choose(self, validation: list[float]) -> None:
        settings, system, key, candidates = self.settings, self.system, self.key, self.candidate_lengths
        chosen = list(self.fits)[int(self.better(validation))]
        self.say(
            f"self-trigger: kept {chosen} ({', '.join(f'{n}: {v:.6g}' for n, v in zip(self.fits, validation))} on "
            f"{settings.validation_episodes} validation episodes)"
        )
        policy = self.fits[chosen]
        best = np.array(candidates)[np.argmax(self.returns, axis=1)]
        hyper = dict(
            settings.to_json(),
            system=str(key),
            recompute_price=system.recompute_price,
            base=self.base,
            base_selection=dict(zip(settings.bases, self.selection)),
            labelled_solves=len(self.rows),
            best_keep_counts={str(c): int(np.sum(best == c)) for c in candidates},
            validation=dict(zip(self.fits, validation)),
            chosen=chosen,
        )
        write_json(self.selected_file, policy.to_json(hyper))
        self.written = policy
        self.finished = True

    def policy(self) -> str:
        return f"self:{self.policy_file}"


def train_self(
    key: str | SystemKey,
    out: Path,
    settings: SelfSettings = SelfSettings(),
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    say=lambda line: None,
    progress: bool = False,
) -> SelfTrigger:
    """Choose the base, label, fit, validate and write ``out`` (the policy file); returns the
    policy. ``key``: a :class:`~etmpc.systems.SystemKey` (a task at a price), or a task's name.
    (:class:`SelfLearner` driven by :func:`etmpc.learning.runner.run`.)"""
    from etmpc.learning.runner import run

    learner = SelfLearner(settings, Path(out))
    run(learner, system_key(key), Path(out).parent, None, workers, False, backend, address, progress=progress, say=say)
    assert learner.written is not None  # a run in a file of its own is never resumed: it chose and wrote
    return learner.written


# What a self-trigger run's selected.json holds (checks.typed_json's hints), the settings as SelfSettings.to_json writes them.
_POLICY = dict(format=str, version=int, domain=str, candidates=list[int], theta=list, mean=list, scale=list, hyperparameters=dict)


def _json_hints(settings: type) -> dict[str, object]:
    """A settings dataclass's fields as its JSON holds them (checks.typed_json's hints): a ``tuple[T, ...]`` as ``list[T]``."""
    hints: dict[str, object] = typing.get_type_hints(settings)
    for name, hint in hints.items():
        if typing.get_origin(hint) is tuple:
            hints[name] = types.GenericAlias(list, (typing.get_args(hint)[0],))
    return hints


_RUN = _json_hints(SelfSettings)
_RUN.update(system=str, recompute_price=float, base=str, labelled_solves=int, best_keep_counts=dict[str, int], chosen=str)
_RUN.update(base_selection=dict[str, float | None], validation=dict[str, float | None])  # a score not finite is null


def read_run(path: Path) -> dict:
    """The content of a finished run's ``selected.json``, each field of its type: the policy as ``self:`` reads it
    (:func:`etmpc.policies.selftrigger.from_json`) and the record of its training, the choice one of those scored."""
    try:
        data = loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path} cannot be read ({exc}); {AGAIN}") from None
    try:
        checks.typed_json(data, _POLICY, "")
        hyper = checks.typed_json(data["hyperparameters"], _RUN, "hyperparameters")
        if hyper["chosen"] not in hyper["validation"] or hyper["base"] not in hyper["bases"]:
            raise checks.BadValue(f"hyperparameters: its choice {hyper['chosen']!r} or base {hyper['base']!r} is not one it had")
    except checks.BadValue as exc:
        raise corrupt(path, exc) from None
    try:
        from_json(data, str(path), None)  # the policy's numbers and sizes, as self: reads them
    except EtmpcError as exc:
        raise EtmpcError(f"{exc}; {AGAIN}") from None
    return data


def _period(spec: str, system) -> int:
    """``T`` of a periodic base (``always``: 1, ``every:T``: T); 0 for anything else."""
    policy = parse_policy(spec, system)
    if isinstance(policy, Always):
        return 1
    return policy.period if isinstance(policy, Every) else 0


def _label_job(job) -> list:
    return label_episode(*job)
