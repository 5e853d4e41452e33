"""A training run's settings (:class:`TrainConfig`) and the streams its random draws come from.

Everything here must match when a run is resumed; see :mod:`etmpc.learning.train` for the run itself.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.learning import dpi
from etmpc.learning.gpomdp import Settings
from etmpc.policies.features import DEFAULT_FEATURES, check_features
from etmpc.systems import SystemKey, canonical, has_levels, system_class
from etmpc.systems.capabilities import RewardFailures, require

TRAIN_ENTROPY = 0x6574_6D70_6321  # "etmpc!"
NORMALISATION_ENTROPY = 0x6E6F_726D  # "norm"
SELECTION_ENTROPY = 0x7365_6C65_6374  # "select"
VALIDATION_ENTROPY = 0x7661_6C69_64  # "valid"
#: The held-out audit stream ("audit"): training-distribution episodes drawn from none of the streams above nor
#: the stored test sets, for reporting only (``etmpc study safety``). Nothing is ever chosen on it: no weight, no
#: seed, no rule, no schedule; a choice made on it would make it one more validation stream.
AUDIT_ENTROPY = 0x6175_6469_74  # "audit"
ALGORITHMS = ("gpomdp", "dpi")
CHECKPOINT_FORMAT = "etmpc-train-checkpoint"
DEFAULT_SEEDS = (0, 1, 2, 3, 4)  # a run's seeds, unless it says


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Everything here must match when a run is resumed."""

    domain: str
    seeds: tuple[int, ...] = DEFAULT_SEEDS
    episodes: int = 1500  # training episodes per seed
    eval_every: int = 150  # evaluate on the test set after every this many episodes (and at 0)
    eval_episodes: int | None = None  # first N test-set episodes (None: all)
    eval_repeats: int = 1  # passes over the test set per evaluation
    normalisation_episodes: int = 20
    gpomdp: Settings = field(default_factory=Settings)
    features: str = DEFAULT_FEATURES  # the policy's feature set (etmpc.policies.learned.FEATURE_SETS)
    algorithm: str = "gpomdp"  # "gpomdp" or "dpi"
    dpi: dpi.Settings = field(default_factory=dpi.Settings)  # used when algorithm == "dpi" (levels: dpi.level_bases)
    validation_episodes: int = 50  # training-distribution episodes that choose selected.json
    recompute_price: float | None = None  # the price of a recompute to train for (None: the task's)
    options: tuple[tuple[str, str], ...] = ()  # the task's options to train under (etmpc.systems.options)

    def __post_init__(self):
        checks.typed(self, finite=True, most=checks.MAX_SEED)  # a checkpoint's too: read from a file
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise EtmpcError(f"seeds must be distinct and at least one, got {self.seeds}")
        for name in ("episodes", "eval_every", "eval_repeats", "normalisation_episodes", "validation_episodes"):
            if not 1 <= getattr(self, name) <= checks.MAX_COUNT:
                raise checks.BadValue(f"{name.replace('_', '-')} must be in 1..{checks.MAX_COUNT:.0e}, got {getattr(self, name)}")
        check_features(self.features)
        if self.algorithm not in ALGORITHMS:
            raise EtmpcError(f"unknown algorithm {self.algorithm!r}; valid: {', '.join(ALGORITHMS)}")
        object.__setattr__(self, "domain", canonical(self.domain))  # the task's own name; a bad one fails here
        object.__setattr__(self, "options", self.system.options)  # a bad price or option fails here; kept canonical
        # On a task with compute levels DPI's default first schedules include iterate:1..5, written out here
        # (so the checkpoint and the policy's hyperparameters say which it chose among).
        object.__setattr__(self, "dpi", dpi.level_bases(self.dpi, has_levels(self.domain)))
        if self.algorithm == "dpi" and self.dpi.failure_cost:  # refused before any work, not in a worker
            require(system_class(self.domain), RewardFailures, "DPI's failure_cost")

    @property
    def system(self) -> SystemKey:
        """The key workers build the system by: the domain, at ``recompute_price`` if one is set, with its options."""
        return SystemKey(self.domain, self.recompute_price, self.options)

    def to_json(self) -> dict:
        data = asdict(self)
        data["seeds"] = list(self.seeds)
        data["options"] = [list(pair) for pair in self.options]
        data["dpi"]["bases"] = list(self.dpi.bases)
        return data

    @classmethod
    def from_json(cls, data: dict) -> TrainConfig:
        data = dict(data)
        data["seeds"] = tuple(data["seeds"])
        data["gpomdp"] = Settings(**data["gpomdp"])
        data.setdefault("features", "paper")  # checkpoints from before feature sets
        data.setdefault("recompute_price", None)  # checkpoints from before prices
        data["options"] = tuple(tuple(pair) for pair in data.get("options", ()))  # and before options
        dpi_settings = dict(data.get("dpi", {}))
        if "bases" in dpi_settings:
            dpi_settings["bases"] = tuple(dpi_settings["bases"])
        data["dpi"] = dpi.Settings(**dpi_settings)
        return cls(**data)

    @property
    def milestones(self) -> list[int]:
        """Episode counts at which the policy is evaluated: 0, eval_every, ..., episodes."""
        points = list(range(0, self.episodes, self.eval_every)) + [self.episodes]
        return sorted(set(points))


MAX_SEEDS = 1000


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"0-4"`` -> (0, 1, 2, 3, 4); ``"1,3,7"``; ``"2"``."""
    seeds: list[int] = []
    try:
        for part in text.split(","):
            first, sep, last = part.partition("-")
            lo = int(first)
            hi = int(last) if sep else lo
            if hi - lo + 1 + len(seeds) > MAX_SEEDS:
                raise EtmpcError(f"bad --seeds {text!r}: at most {MAX_SEEDS} seeds")
            seeds += range(lo, hi + 1)
    except ValueError:
        raise EtmpcError(f"bad --seeds {text!r}: use a range like 0-4 or a list like 0,2,5") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise EtmpcError(f"bad --seeds {text!r}: non-negative and distinct")
    return tuple(seeds)
