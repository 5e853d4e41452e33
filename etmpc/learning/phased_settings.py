"""What a GPOMDP or DPI run is asked for (``etmpc train --algorithm gpomdp|dpi --set NAME=VALUE``): the
settings both share (:class:`PhasedSettings`) and each algorithm's own (:class:`GpomdpSettings`,
:class:`DpiSettings`), checked when made; the :class:`~etmpc.learning.config.TrainConfig` they make on a task
(:func:`train_config`) and the identity a resumed run is checked against (:func:`identity_of`). The run itself is
:mod:`etmpc.learning.phased`."""

from __future__ import annotations

from dataclasses import dataclass, fields

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.learning import dpi, gpomdp
from etmpc.learning.config import TrainConfig
from etmpc.policies.features import DEFAULT_FEATURES, check_features
from etmpc.systems import SystemKey


@dataclass(frozen=True)
class PhasedSettings:
    """What GPOMDP and DPI runs share (``etmpc train --set NAME=VALUE``)."""

    episodes: int = 1500  # training episodes per seed
    eval_every: int = 150  # evaluate on the test set after every this many episodes (and at 0)
    eval_episodes: int | None = None  # first N test-set episodes (None: all)
    eval_repeats: int = 1  # passes over the test set per evaluation
    normalisation_episodes: int = 20
    features: str = DEFAULT_FEATURES
    validation_episodes: int = 50  # training-distribution episodes that choose selected.json
    record_episodes: int = 0  # test-set episodes per seed recorded at each evaluation (changes no result)

    def __post_init__(self):
        checks.typed(self, finite=True, most=checks.MAX_COUNT)
        for name in ("episodes", "eval_every", "eval_repeats", "normalisation_episodes", "validation_episodes"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise EtmpcError(f"{name.replace('_', '-')} must be an integer >= 1, got {getattr(self, name)!r}")
        if self.eval_episodes is not None and (not isinstance(self.eval_episodes, int) or self.eval_episodes < 1):
            raise EtmpcError(f"eval-episodes must be an integer >= 1 or None, got {self.eval_episodes!r}")
        if not isinstance(self.record_episodes, int) or self.record_episodes < 0:
            raise EtmpcError(f"record episodes must be >= 0, got {self.record_episodes}")
        check_features(self.features)
        try:
            self.algorithm_settings  # the algorithm's own checks, as one line
        except ValueError as exc:
            raise EtmpcError(str(exc)) from None

    @property
    def algorithm_settings(self):
        """The algorithm's own settings (:class:`etmpc.learning.gpomdp.Settings`, ...), built from these."""
        return None


@dataclass(frozen=True)
class GpomdpSettings(PhasedSettings):
    """A GPOMDP run: :class:`PhasedSettings` and :class:`etmpc.learning.gpomdp.Settings`' fields."""

    discount: float = 0.975
    learning_rate: float = 0.05
    baseline: str = "none"
    scale: str = "none"

    @property
    def algorithm_settings(self) -> gpomdp.Settings:
        return gpomdp.Settings(self.discount, self.learning_rate, self.baseline, self.scale)


@dataclass(frozen=True)
class DpiSettings(PhasedSettings):
    """A DPI run: :class:`PhasedSettings` and :class:`etmpc.learning.dpi.Settings`' fields."""

    futures: int = 4
    horizon: int = 20
    states_per_episode: int = 25
    ridge: float = 1e-2
    bases: tuple[str, ...] = dpi.BASES  # on a task with compute levels, by default also dpi.LEVEL_BASES
    selection_episodes: int = 30
    failure_cost: float = 0.0  # each failure in a labelling rollout costs this much more (dpi.Settings)

    @property
    def algorithm_settings(self) -> dpi.Settings:
        return dpi.Settings(**{f.name: getattr(self, f.name) for f in fields(dpi.Settings)})


# The settings a TrainConfig holds as they are (record_episodes changes no result: it is the run's, not the config's).
SHARED = tuple(f.name for f in fields(PhasedSettings) if f.name != "record_episodes")


def train_config(settings: PhasedSettings, algorithm: str, key: SystemKey, seeds: tuple[int, ...]) -> TrainConfig:
    """The :class:`TrainConfig` of a run of ``settings`` by ``algorithm`` (``"gpomdp"`` or ``"dpi"``) on ``key``'s
    task (at its price, with its options) with ``seeds``."""
    own = {"gpomdp": settings.algorithm_settings} if algorithm == "gpomdp" else {"dpi": settings.algorithm_settings}
    return TrainConfig(
        key.task,
        seeds,
        **{n: getattr(settings, n) for n in SHARED},
        algorithm=algorithm,
        recompute_price=key.recompute_price,
        options=key.options,
        **own,
    )


def identity_of(config: TrainConfig) -> dict:
    """A run's :meth:`~etmpc.learning.base.Learner.identity`: the task its workers build (at its price, with its
    options), and the rest of its configuration (the seeds too: a run is resumed with the seeds it trains)."""
    settings = {k: v for k, v in config.to_json().items() if k not in ("domain", "recompute_price", "options")}
    return {"task": str(config.system), "settings": settings}
