"""The whole trade-off curve: control objective against recomputes, over prices of a recompute.

``etmpc sweep TASK`` answers the classic question of event-triggered control: *at an equal number of
recomputes, does a state-dependent policy beat a periodic one, and by how much?* On the same
test-set episodes it plays

* every periodic schedule ``every:T``, T = 1 … N (``every:1`` is ``always``, ``every:N`` is
  ``never``): the **periodic front**;
* a grid of event triggers ``threshold:X`` spanning the same range of recompute rates;

once (their decisions do not depend on the price: only their objective does, and it is recomputed
for every price from the control objective and the recomputes of each episode), and, for every
price ``p``,

* the rollout policy ``rollout:BEST:K:H`` over the best periodic schedule at ``p``, which optimises
  the objective at ``p`` (see :mod:`etmpc.policies.rollout`);
* the oracle ``oracle:BEST``: the reference for what a one-step lookahead could gain at ``p``, not a policy;
* a learned policy trained at ``p`` with the default learner (DPI on the ``error`` features, see
  :mod:`etmpc.learning.dpi`), chosen among its seeds on training-distribution episodes, never the test set;
* a self-triggering policy ``self:PATH`` trained at ``p`` (see :mod:`etmpc.policies.selftrigger`): at each
  solve it announces how long the plan will be kept.

Comparisons are paired per episode. *At an equal rate*: the periodic front (the schedules no other
schedule beats in both rate and control objective) is interpolated per episode between the two
of its schedules whose mean rates bracket the policy's, with the weights that make
the front's mean rate the policy's, so the difference of control objectives is a difference at the
same mean number of recomputes (and so at the same mean price paid). Against the *nearest
periodic schedule*: the objective at ``p``, recomputes included.

Outputs (all written atomically; a directory is resumable and never written into by another run):
``settings.json``, ``fixed.json``, ``price_<i>.json``, ``learned_<i>.json`` and ``self_<i>.json``
(evaluations), ``train_<i>/`` (the training run at price ``i``), ``self_policy_<i>.json`` (the
self-trigger trained at price ``i``), ``pareto.json``, ``pareto.png`` and ``SWEEP.md``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_outputs, refuse_foreign, what_differs, write_json, write_text
from etmpc.common.progress import stage
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.testsets import check_options_act, default_path, load
from etmpc.evaluation.backends import shared_pools
from etmpc.experiments.stages import trained
from etmpc.experiments.pareto import best_periodic, build_pareto, report_section
from etmpc.learning import dpi
from etmpc.learning.config import TrainConfig
from etmpc.learning.selftrigger import SelfSettings, train_self
from etmpc.systems import SystemKey, distinct, make_system, names
from etmpc.systems.capabilities import Experiments, require
from etmpc.views.curves import draw_pareto
from etmpc.views.figures import save_png_atomically

MAX_PRICES = 50


@dataclass(frozen=True)
class LearnerSettings:
    """The default learner at each price, smaller than ``reproduce``'s: DPI, whose first policy
    rolls out over the best of ``bases`` (wide enough for every price) on training episodes."""

    seeds: tuple[int, ...] = (0, 1)
    episodes: int = 40  # training episodes per seed: 2 DPI iterations of 20
    eval_every: int = 20
    eval_episodes: int = 1  # the learning curve's test-set episodes (reported, never used to choose)
    labels: int = 15  # decisions labelled per training episode
    futures: int = 2
    horizon: int = 10
    validation_episodes: int = 20  # training-distribution episodes that choose among the seeds
    bases: tuple[str, ...] = ("always", "every:2", "every:3", "every:5", "every:8", "every:12", "every:20")
    selection_episodes: int = 20

    def config(self, domain: str, price: float | None, options=()) -> TrainConfig:
        return TrainConfig(
            domain,
            self.seeds,
            self.episodes,
            self.eval_every,
            self.eval_episodes,
            algorithm="dpi",
            dpi=dpi.Settings(
                self.futures,
                make_system(domain).benchmark.capped(self.horizon),
                self.labels,
                bases=self.bases,
                selection_episodes=self.selection_episodes,
            ),
            validation_episodes=self.validation_episodes,
            recompute_price=price,
            options=tuple(options),
        )


QUICK_LEARNER = LearnerSettings(
    seeds=(0,), episodes=4, eval_every=2, labels=5, futures=2, horizon=10, validation_episodes=3, selection_episodes=2
)


QUICK_SELF = SelfSettings(selection_episodes=2, episodes=3, solves_per_episode=3, validation_episodes=2)


@dataclass(frozen=True)
class SweepSettings:
    prices: tuple[float, ...]
    episodes: int  # the first test-set episodes, for every policy
    thresholds: tuple[float, ...]
    futures: int = 4  # K of the rollout policy
    horizon: int = 20  # H of the rollout policy
    quick: bool = False
    learner: LearnerSettings | None = LearnerSettings()  # None: no learned policies
    self_trigger: SelfSettings | None = SelfSettings()  # None: no self-triggering policies
    options: tuple[tuple[str, str], ...] = ()  # the task's options (etmpc.systems.options), for every stage

    @classmethod
    def default(cls, domain: str, prices=None, episodes: int | None = None, quick: bool = False, options=()) -> SweepSettings:
        system = make_system(domain)
        options = SystemKey(domain, None, options).options  # checked, canonical
        require(system, Experiments, "etmpc sweep")
        benchmark = system.benchmark  # the task's prices and threshold levels
        prices = benchmark.prices if prices is None else tuple(prices)
        if not 1 <= len(prices) <= MAX_PRICES:
            raise EtmpcError(f"give 1 to {MAX_PRICES} prices, got {len(prices)}")
        prices = tuple(SystemKey(domain, p).recompute_price for p in prices)  # each checked
        if len(set(prices)) != len(prices):
            raise EtmpcError(f"a price is given twice: {', '.join(f'{p:g}' for p in prices)}")
        if quick:
            return cls(
                prices,
                episodes or 3,
                benchmark.sweep_thresholds[::2],
                futures=2,
                horizon=benchmark.capped(10),
                quick=True,
                learner=QUICK_LEARNER,
                self_trigger=QUICK_SELF,
                options=options,
            )
        return cls(
            prices,
            episodes or benchmark.sweep_episodes,
            benchmark.sweep_thresholds,
            futures=benchmark.sweep_futures,
            horizon=benchmark.capped(cls.horizon),
            self_trigger=SelfSettings() if benchmark.sweep_self_trigger else None,
            options=options,
        )

    def to_json(self) -> dict:
        data = _lists(asdict(self))
        if not self.options:  # a sweep without options is written as before, so an older one continues
            del data["options"]
        return data

    def key(self, domain: str, price: float | None = None) -> SystemKey:
        """The task the sweep plays, at ``price`` (None: the task's own), with its options."""
        return SystemKey(domain, price, self.options)


def plan(
    tasks: list[str] | None, prices=None, episodes: int | None = None, quick: bool = False, options=()
) -> dict[str, SweepSettings]:
    """The settings of a sweep of ``tasks`` (default: every task), each checked before any work:
    known, given once, priced sensibly, and asking no more episodes than its stored test set has; ``options``: the
    tasks' options (the same for every task, checked against each)."""
    tasks = distinct(tasks or names())
    settings = {task: SweepSettings.default(task, prices, episodes, quick, options) for task in tasks}
    for task, chosen in settings.items():
        system = make_system(task)
        check_options_act(chosen.key(task), takes_test_set=False)  # every stage plays the stored test set
        stored = load(default_path(system.domain, system.task), system.domain, system.task)
        if chosen.episodes > stored.episodes:
            raise EtmpcError(f"--episodes must be in 1..{stored.episodes} for the {task} test set, got {chosen.episodes}")
    return settings


def _lists(value):
    """``value`` as JSON reads it back: tuples as lists, at any depth."""
    if isinstance(value, dict):
        return {k: _lists(v) for k, v in value.items()}
    return [_lists(v) for v in value] if isinstance(value, (tuple, list)) else value


def _ours(name: str) -> bool:
    return (
        name in ("settings.json", "fixed.json", "pareto.json", "pareto.png", "SWEEP.md")
        or (name.startswith(("price_", "learned_", "self_")) and name.endswith(".json"))
        or name.startswith("train_")
    )


def check_directory(out: Path, domain: str, settings: SweepSettings, option: str = "--out") -> bool:
    """Raise unless ``out`` can hold this sweep: new, empty, or the same sweep (then True: it
    continues), a directory, and none of its files a FIFO or a device (which reading back would hang on).
    Writes nothing, so every task's directory is checked before any work."""
    check_outputs({}, {option: out}, writes={option: _ours})
    path = out / "settings.json"
    if not path.exists():
        refuse_foreign(out, lambda name: False, "sweep")
        return False
    try:
        stored = loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path} is unreadable ({exc}); move it away to start afresh") from None
    if stored != _settings_json(domain, settings):
        raise EtmpcError(
            f"{out} holds a sweep with other settings ({what_differs(stored, _settings_json(domain, settings))}); "
            "use another --out"
        )
    refuse_foreign(out, _ours, "sweep")
    return True


def _settings_json(domain: str, settings: SweepSettings) -> dict:
    return {"format": "etmpc-sweep", "domain": domain, "settings": settings.to_json()}


def _start(out: Path, domain: str, settings: SweepSettings) -> None:
    """A new run in a new or empty directory, or the same run continued; never another's files."""
    if not check_directory(out, domain, settings):
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "settings.json", _settings_json(domain, settings))


def _stage(path: Path, **kwargs) -> dict:
    """An evaluation made once (a complete file from an earlier invocation is reused), with its
    wall time and number of workers."""
    if path.exists():
        return loads(path.read_text())
    started = time.perf_counter()
    data = evaluate(**kwargs).to_json()
    data["cost"] = {"wall_seconds": time.perf_counter() - started, "workers": kwargs.get("workers")}
    write_json(path, data)
    return data


def sweep(
    domain: str,
    out: Path,
    settings: SweepSettings,
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    say=lambda line: None,
) -> dict:
    """Run (or continue) the sweep of ``domain`` into ``out``; returns ``pareto.json``'s content."""
    with shared_pools():  # one pool of workers for every stage
        return _sweep(domain, Path(out), settings, workers, backend, address, progress, say)


def _sweep(
    domain: str, out: Path, settings: SweepSettings, workers: int, backend: str, address: str | None, progress: bool, say
) -> dict:
    system = settings.key(domain).make()  # with the options (a horizon among them sets the periodic schedules)
    _start(out, domain, settings)
    started = time.perf_counter()
    run = dict(episodes=settings.episodes, workers=workers, backend=backend, address=address, progress=progress)
    periodic = [f"every:{t}" for t in range(1, system.horizon + 1)]
    events = [f"threshold:{x:g}" for x in settings.thresholds]
    say(f"{domain}: {len(periodic)} periodic schedules and {len(events)} event triggers")
    with stage(f"{domain}: fixed policies"):  # each stage named in the progress lines
        fixed = _stage(out / "fixed.json", task=settings.key(domain), policies=periodic + events, **run)
    priced = []
    for i, price in enumerate(settings.prices):
        best = best_periodic(fixed, periodic, price, system.objective_sense)
        say(f"{domain}: price {price:g}: rollout and oracle over {best}")
        specs = [f"rollout:{best}:{settings.futures}:{settings.horizon}", f"oracle:{best}"]
        at = f"{domain}: price {price:g} ({i + 1}/{len(settings.prices)})"
        with stage(f"{at}: rollout and oracle"):
            evaluation = _stage(out / f"price_{i}.json", task=settings.key(domain, price), policies=specs, **run)
        if settings.learner is not None:
            with stage(f"{at}: the default learner"):
                evaluation = _merge(evaluation, _learned(out, i, settings.key(domain, price), settings.learner, run))
        if settings.self_trigger is not None:
            with stage(f"{at}: the self-trigger"):
                evaluation = _merge(evaluation, _self(out, i, settings.key(domain, price), settings.self_trigger, run, say))
        priced.append(evaluation)
    pareto = build_pareto(domain, system.objective_sense, settings, fixed, periodic, events, priced)
    pareto["wall_seconds_this_invocation"] = time.perf_counter() - started
    pareto["cpu_seconds_of_evaluations"] = sum(e["cost"]["wall_seconds"] * (e["cost"]["workers"] or 1) for e in [fixed, *priced])
    write_json(out / "pareto.json", pareto)
    save_png_atomically(draw_pareto(pareto), out / "pareto.png")
    write_text(out / "SWEEP.md", "\n".join(report_section(pareto)) + "\n")
    return pareto


def _learned(out: Path, i: int, key: SystemKey, learner: LearnerSettings, run: dict) -> dict:
    """The default learner trained on ``key`` (the task at a price, with the sweep's options; ``train_<i>/``,
    resumable), its chosen policy evaluated on the sweep's episodes there (``learned_<i>.json``)."""
    path, train_dir = out / f"learned_{i}.json", out / f"train_{i}"
    if path.exists():
        return loads(path.read_text())
    trained(learner.config(key.task, key.recompute_price, key.options), train_dir, run, run["progress"])
    return _stage(path, task=key, policies=[f"rl:{train_dir / 'selected.json'}"], **run)


def _self(out: Path, i: int, key: SystemKey, settings: SelfSettings, run: dict, say) -> dict:
    """The self-trigger trained on ``key`` (``self_policy_<i>.json``, kept once written), evaluated on the
    sweep's episodes there (``self_<i>.json``)."""
    path, policy = out / f"self_{i}.json", out / f"self_policy_{i}.json"
    if path.exists():
        return loads(path.read_text())
    if not policy.exists():
        train_self(key, policy, settings, run["workers"], run["backend"], run["address"], say=say, progress=run["progress"])
    return _stage(path, task=key, policies=[f"self:{policy}"], **run)


def _merge(a: dict, b: dict) -> dict:
    """Two evaluations of the same episodes as one (their policies and runs side by side)."""
    return {
        **a,
        "policies": {**a["policies"], **b["policies"]},
        "runs": a["runs"] + b["runs"],
        "cost": {"wall_seconds": a["cost"]["wall_seconds"] + b["cost"]["wall_seconds"], "workers": a["cost"]["workers"]},
    }
