"""etmpc's benchmarks, each measuring two things side by side in one run: alternating rounds, so that whatever
else the machine does falls on both sides.

    python scripts/bench.py env [TASK ...] [--episodes 20] [--rounds 3]
    python scripts/bench.py recording [TASK ...] [--policy SPEC ...] [--rounds 2] [--workers 2]
    python scripts/bench.py training [TASK] [--policy PATH ...] [--episodes 20] [--workers 2] [--backend ray] [--json PATH]
    python scripts/bench.py versus REV [TASK ...] [--episodes 5] [--rounds 3]
    python scripts/bench.py lookahead [--episodes 5] [--json PATH] | --compare OLD.json NEW.json
    python scripts/bench.py sb3 [--task cart_pendulum] [--model policies/cart_pendulum/balance/ppo.zip]
                                [--episodes 20] [--rounds 5]

``python scripts/bench.py COMMAND --help`` says what each one measures. Every command imports etmpc only
when it runs, so that ``PYTHONPATH=OTHER_TREE`` measures another tree (``lookahead``) and a worker process
started by ``training`` imports only what its job needs.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def alternate(rounds: int, **sides) -> dict[str, list]:
    """Each side's result per round, the sides called in turn within each round (``name=callable``)."""
    results = {name: [] for name in sides}
    for _ in range(rounds):
        for name, run in sides.items():
            results[name].append(run())
    return results


# env ------------------------------------------------------------------------------------------------------------


def env(args) -> int:
    """Steps per second of the trigger environment (gymnasium) against the loop's own.

    The same training-distribution episodes are played under ``every:3``, once by ``run_episode`` (the loop
    ``evaluate`` plays) and once through ``gymnasium.make("etmpc/...")`` by an agent answering as ``every:3``
    does; alternating rounds, the best of each. Prints steps/s of both and their ratio.
    """
    import gymnasium as gym
    import numpy as np

    import etmpc  # noqa: F401  (registers the environments)
    from etmpc.envs.registration import env_id
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy
    from etmpc.systems import make_system

    def loop_rate(system, loop_env, episodes) -> float:
        policy, steps = parse_policy("every:3", system), 0
        start = time.perf_counter()
        for episode in episodes:
            steps += run_episode(system, loop_env, policy, None, episode).steps
        return steps / (time.perf_counter() - start)

    def env_rate(gym_env, episodes) -> float:
        core, steps = gym_env.unwrapped.core, 0
        start = time.perf_counter()
        for episode in episodes:
            core.loop.reset(episode)  # the same episodes as the loop's (reset draws its own)
            done = False
            while not done:
                _, _, terminated, truncated, _ = gym_env.step(int(core.loop.age >= 3))
                steps += 1
                done = terminated or truncated
        return steps / (time.perf_counter() - start)

    for task in args.tasks:
        system = make_system(task)
        loop_env, gym_env = system.make_env(), gym.make(env_id(task))
        gym_env.reset(seed=0)
        rng = np.random.default_rng(0)
        episodes = [system.draw_episode(rng) for _ in range(args.episodes)]
        rates = alternate(
            args.rounds, loop=lambda: loop_rate(system, loop_env, episodes), environment=lambda: env_rate(gym_env, episodes)
        )
        loop_best, env_best = max(rates["loop"]), max(rates["environment"])
        print(
            f"{task}: loop {loop_best:,.0f} steps/s, environment {env_best:,.0f} steps/s, "
            f"loop / environment {loop_best / env_best:.2f} (best of {args.rounds} alternating rounds, "
            f"{args.episodes} episodes each, every:3)"
        )
    return 0


# recording ------------------------------------------------------------------------------------------------------


def recording(args) -> int:
    """What recording costs: the same evaluation with and without ``--record``.

    For each task and policy, alternates plain and recorded evaluations of the whole test set (``--rounds``
    times each, best of the rounds reported) and prints the wall times, their ratio and the recording's size.
    """
    import tempfile

    from etmpc import evaluate  # with the Recorder filled in: the recorded runs write .rrd files

    def timed(task, spec, **options) -> tuple[float, object]:
        started = time.perf_counter()
        result = evaluate(task, [spec], workers=args.workers, progress=False, **options)
        return time.perf_counter() - started, result

    policies = args.policy or ["always", "every:3"]
    print(f"{'task':<15}{'policy':<12}{'plain s':>9}{'recorded s':>12}{'ratio':>8}{'size MB':>10}{'kB/episode':>12}")
    with tempfile.TemporaryDirectory() as tmp:
        for task in args.tasks:
            for spec in policies:
                path = Path(tmp) / f"{task}.rrd"
                runs = alternate(args.rounds, plain=lambda: timed(task, spec), recorded=lambda: timed(task, spec, record=path))
                plain, recorded = min(s for s, _ in runs["plain"]), min(s for s, _ in runs["recorded"])
                episodes = len(runs["plain"][-1][1].runs)
                size = path.stat().st_size
                print(
                    f"{task:<15}{spec:<12}{plain:>9.2f}{recorded:>12.2f}{recorded / plain:>8.2f}"
                    f"{size / 1e6:>10.1f}{size / 1e3 / episodes:>12.0f}"
                )
    return 0


# training -------------------------------------------------------------------------------------------------------


def peak_rss_mib() -> float:
    """This process's peak resident memory in MiB: ``VmHWM`` of its own address space where Linux
    gives it (``ru_maxrss`` survives ``exec``, so a script started by a 1 GiB test runner would
    report 1 GiB), else ``ru_maxrss``."""
    import resource

    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _training_job(job: tuple) -> dict:
    """One measurement on a worker: ``episodes`` training or evaluation episodes of one policy."""
    import numpy as np

    from etmpc.evaluation.workers import context
    from etmpc.learning.gpomdp import Learner, Settings
    from etmpc.learning.jobs import _learner_to_json, evaluate_theta, train_block

    kind, domain, policy_json, seed, episodes = job
    system, _, testset = context(domain)
    started = time.perf_counter()
    if kind == "train":
        learner = _learner_to_json(Learner.start(np.array(policy_json["theta"]), Settings(), system.episode_steps))
        _, stats = train_block(domain, policy_json, learner, seed, 0, episodes)
        recomputes = float(np.mean([s["recomputes"] for s in stats]))
    else:
        results = [evaluate_theta(domain, testset.sha256, policy_json, 0, e % testset.episodes) for e in range(episodes)]
        recomputes = float(np.mean([r[2] for r in results]))
    elapsed = time.perf_counter() - started
    return {
        "kind": kind,
        "seed": seed,
        "episodes": episodes,
        "seconds": elapsed,
        "recomputes": recomputes,
        "pid": os.getpid(),
        "maxrss_mib": peak_rss_mib(),
    }


def training(args) -> int:
    """Training throughput and memory: how fast GPOMDP training runs at its start and its end, how much
    memory a worker needs, and what that means for the paper's protocol.

    Measured side by side in one run, on the worker processes that training itself uses:

    - training episodes/s of one worker at the start (the initial policy recomputes ~95 % of the time)
      and at the end (each ``--policy``, e.g. a run's ``last.json``; without one, a policy that keeps
      its plan ~95 % of the time stands in as the cheap extreme);
    - test-set evaluation episodes/s for the same policies;
    - the peak resident memory of every worker process (``VmHWM``: ``ru_maxrss`` would also count the
      peak of whatever process started this one, since Linux keeps it across ``exec``);
    - the paper protocol's wall time projected from these rates (5 seeds x 1500 episodes, evaluated
      every 150 on the 100-episode test set), to set beside a real ``etmpc train`` run.
    """
    import numpy as np

    from etmpc.evaluation.backends import make_backend
    from etmpc.evaluation.workers import context
    from etmpc.learning.jobs import normalisation_states
    from etmpc.policies.learned import INITIAL_KEEP_LOGIT, LogisticPolicy, Normalisation, load_policy

    system = context(args.task)[0]
    states = np.concatenate([normalisation_states(args.task, i) for i in range(10)])
    initial = LogisticPolicy.initial(Normalisation.fit(states), args.task, {})
    policies = {"start (initial policy)": initial.to_json()}
    if args.policy:
        for path in args.policy:
            policies[f"end ({path})"] = load_policy(path, args.task, len(system.error_weights)).to_json()
    else:
        keeper = initial.with_theta(np.concatenate([np.zeros(initial.theta.size - 1), [-INITIAL_KEEP_LOGIT]]))
        policies["mostly keeps (bias +3)"] = keeper.to_json()

    # Two measurements per policy and kind, so each worker does both kinds of work.
    jobs = [
        (kind, args.task, policy, seed, args.episodes)
        for policy in policies.values()
        for kind in ("train", "evaluate")
        for seed in range(args.workers)
    ]
    started = time.perf_counter()
    with make_backend(args.backend, args.workers) as backend:
        results = backend.map(_training_job, jobs)
    wall = time.perf_counter() - started

    rates = {}
    print(
        f"{args.task}: {args.episodes} episodes per measurement, {args.workers} workers ({args.backend}), "
        f"measured together in {wall:.1f} s"
    )
    print(f"{'policy':<44}{'train ep/s':>12}{'eval ep/s':>12}{'recomputes':>12}   (per worker)")
    for i, name in enumerate(policies):
        mine = results[i * 2 * args.workers : (i + 1) * 2 * args.workers]
        rate = {
            kind: sum(r["episodes"] for r in mine if r["kind"] == kind) / sum(r["seconds"] for r in mine if r["kind"] == kind)
            for kind in ("train", "evaluate")
        }
        recomputes = np.mean([r["recomputes"] for r in mine if r["kind"] == "train"])
        rates[name] = dict(rate, recomputes=float(recomputes))
        print(f"{name:<44}{rate['train']:>12.2f}{rate['evaluate']:>12.2f}{recomputes:>12.1f}")

    peak = {}
    for r in results:
        peak[r["pid"]] = max(peak.get(r["pid"], 0.0), r["maxrss_mib"])
    print(f"peak resident memory per worker: {', '.join(f'{v:.0f} MiB' for v in peak.values())} (target <= 1024 MiB)")

    seeds, episodes, every, test_episodes = 5, 1500, 150, 100
    train_episodes = seeds * episodes
    eval_episodes = seeds * (episodes // every + 1) * test_episodes
    projections = {}
    for name, rate in rates.items():
        projections[name] = (train_episodes / rate["train"] + eval_episodes / rate["evaluate"]) / args.workers
    start_name = next(iter(rates))
    print(
        f"paper protocol ({seeds} seeds x {episodes} episodes, {eval_episodes} evaluation episodes), "
        f"projected on {args.workers} workers:"
    )
    for name, seconds in projections.items():
        print(f"  at the rates of {name}: {seconds / 60:.1f} min (target <= 15 min)")
    print(f"  the real run lies between these: it starts at the rates of '{start_name}'")

    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "task": args.task,
                    "episodes": args.episodes,
                    "workers": args.workers,
                    "backend": args.backend,
                    "wall_seconds": wall,
                    "rates": rates,
                    "peak_rss_mib": list(peak.values()),
                    "protocol_projection_seconds": projections,
                    "results": results,
                },
                f,
                indent=2,
            )
        print(f"wrote {args.json}")
    return 0


# versus ---------------------------------------------------------------------------------------------------------


def _bench(tree: Path, tasks: list[str], episodes: int, out: Path) -> dict:
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(tree), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    subprocess.run(
        [sys.executable, "-m", "etmpc.cli", "bench", *tasks, "--episodes", str(episodes), "--no-reference", "--json", str(out)],
        cwd=tree,
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return json.loads(out.read_text())


def _metrics(figures: dict) -> dict[str, tuple[float, bool]]:
    """name -> (value, higher is better)."""
    m = {
        "MPC solve median (ms)": (figures["mpc_solve"]["median_ms"], False),
        "rest of a step, dm_env path (us)": (figures["rest_of_step"]["median_us"], False),
    }
    if "rollout_step" in figures:
        m["rollout step, no solve (us)"] = (figures["rollout_step"]["median_us"], False)
    for spec, rate in figures["episodes_per_second"].items():
        m[f"episodes/s {spec}"] = (rate, True)
    return m


def versus(args) -> int:
    """``etmpc bench`` of this tree against an earlier commit.

    Checks ``REV`` out into a temporary git worktree, then alternates ``etmpc bench --no-reference`` of the
    old tree and of this one (each in its own process, ``--rounds`` times each), and prints, per task, the
    best round of each side and their ratio: the MPC solve median, the rest of a step, the rollout step
    (where the old tree has one) and episodes per second under each policy both trees bench. Best of the
    rounds, because on a shared machine noise only ever adds time.
    """
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="etmpc-versus-") as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(old), args.rev],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            rounds = {"old": [], "new": []}
            for r in range(args.rounds):
                for side, tree in (("old", old), ("new", REPO)):
                    rounds[side].append(_bench(tree, args.tasks, args.episodes, Path(tmp) / f"{side}{r}.json"))
                    print(f"round {r + 1}/{args.rounds}: {side} done", file=sys.stderr, flush=True)
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(old)], check=False)

    rev = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", args.rev], capture_output=True, text=True
    ).stdout.strip()
    print(f"best of {args.rounds} rounds each, {args.episodes} test-set episodes; old = {rev}, new = this tree")
    for task in args.tasks:
        print(f"\n{task}\n{'':38}{'old':>10}{'new':>10}{'new better by':>15}")
        old_m = [_metrics(f[task]) for f in rounds["old"]]
        new_m = [_metrics(f[task]) for f in rounds["new"]]
        for name, (_, higher) in new_m[0].items():
            pick = max if higher else min
            new_v = pick(m[name][0] for m in new_m)
            if name not in old_m[0]:
                print(f"{name:38}{'-':>10}{new_v:>10.3f}")
                continue
            old_v = pick(m[name][0] for m in old_m)
            print(f"{name:38}{old_v:>10.3f}{new_v:>10.3f}{(new_v / old_v if higher else old_v / new_v):>14.2f}x")
    return 0


# lookahead ------------------------------------------------------------------------------------------------------

LOOKAHEAD_TASKS = ("cart_pendulum", "cart_pendulum/kicks", "battery", "reacher/jumps")
FUTURES = 4  # the leaderboard's rollout meter


def lookahead(args) -> int:
    """CPU time per episode of the leaderboard's two slowest rows: the oracle and the rollout meter.

    Plays ``oracle:BEST`` and ``rollout:BEST:4:H`` (the leaderboard's specs) on the first episodes of each
    task's stored test set, one process, and prints the CPU seconds per episode and a digest of the
    objectives (so two trees that give the same numbers show the same digest). Run it once per tree, side
    by side, to compare an old tree with a new one:

        git worktree add /tmp/old-tree OLD_COMMIT
        PYTHONPATH=/tmp/old-tree python scripts/bench.py lookahead --json old.json
        PYTHONPATH=. python scripts/bench.py lookahead --json new.json
        python scripts/bench.py lookahead --compare old.json new.json
    """
    if args.compare:
        old, new = (json.loads(Path(p).read_text()) for p in args.compare)
        print(f"{'row':56s} {'old s/ep':>9s} {'new s/ep':>9s} {'speed-up':>9s}  same numbers")
        for row, a in old["rows"].items():
            b = new["rows"][row]
            print(
                f"{row:56s} {a['cpu_s_per_episode']:9.3f} {b['cpu_s_per_episode']:9.3f} "
                f"{a['cpu_s_per_episode'] / b['cpu_s_per_episode']:8.2f}x  {a['objectives_sha256'] == b['objectives_sha256']}"
            )
        return 0

    import hashlib
    import platform

    import etmpc
    from etmpc.evaluation.evaluate import evaluate
    from etmpc.evaluation.references import references_path
    from etmpc.systems import make_system

    out = {"etmpc": etmpc.__file__, "machine": platform.processor() or platform.machine(), "rows": {}}
    for task in LOOKAHEAD_TASKS:
        best = json.loads(references_path(task).read_text())["best"]
        horizon = make_system(task).benchmark.lookahead
        for spec in (f"oracle:{best}", f"rollout:{best}:{FUTURES}:{horizon}"):
            evaluate(task, [spec], episodes=1, workers=1, progress=False)  # warm: compiled code, caches
            started = time.process_time()
            result = evaluate(task, [spec], episodes=args.episodes, workers=1, progress=False)
            cpu = (time.process_time() - started) / args.episodes
            objectives = [r.objective for r in sorted(result.runs, key=lambda r: r.episode)]
            digest = hashlib.sha256(json.dumps(objectives).encode()).hexdigest()[:16]
            out["rows"][f"{task} {spec}"] = {"cpu_s_per_episode": cpu, "objectives_sha256": digest}
            print(f"{task:22s} {spec:32s} {cpu:7.3f} s/episode  objectives {digest}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


# sb3 ------------------------------------------------------------------------------------------------------------


def _timed(decide, inputs) -> tuple[list[float], list[int]]:
    """Microseconds of each call of ``decide`` on each input, and its answers."""
    clock, times, answers = time.perf_counter_ns, [], []
    for value in inputs:
        start = clock()
        answer = decide(value)
        times.append((clock() - start) / 1000)
        answers.append(int(answer))
    return times, answers


def sb3(args) -> int:
    """Microseconds per ``sb3:`` decision: Stable-Baselines3's ``predict`` (what ``sb3:`` called before)
    against the numpy network (what it calls now).

    The augmented states come from real test-set episodes played by the model. Each decision is timed on
    its own (``perf_counter_ns``), old and new alternating in rounds, and the median is reported: with the
    observation's computation and normalisation (what the loop pays per step), and for the network alone on
    the normalised observation. PyTorch runs on one thread, as the workers ran it. Both answers are compared
    at every call: the command fails if they ever differ.
    """
    import statistics

    import numpy as np
    import torch
    from stable_baselines3 import PPO

    from etmpc.evaluation.workers import play_test_episode
    from etmpc.loop import AugmentedState
    from etmpc.policies.sb3 import load_sb3

    class Recorder:
        """The model deciding, with a copy of every augmented state it was shown."""

        stochastic = False
        spec = "sb3-recorded"

        def __init__(self, policy):
            self.policy, self.states = policy, []

        def decide(self, s, rng) -> bool:
            self.states.append(
                AugmentedState(np.array(s.x), np.array(s.x_plan), s.age, np.array(s.x_predicted), s.plan, s.observation)
            )
            return self.policy.decide(s, rng)

    torch.set_num_threads(1)
    policy = load_sb3(args.model, args.task)
    model = PPO.load(args.model, device="cpu")  # the old path: trusted files only
    recorder = Recorder(policy)
    for episode in range(args.episodes):
        play_test_episode(args.task, recorder, 0, 0, episode)
    states = recorder.states
    observations = [policy.normalised(s) for s in states]

    cases = {
        "observation + network": (
            states,
            lambda s: int(model.predict(policy.normalised(s), deterministic=True)[0]),
            lambda s: policy.decide(s, None),
        ),
        "network alone": (observations, lambda x: int(model.predict(x, deterministic=True)[0]), policy.network.action),
    }
    medians = {}
    for name, (inputs, old, new) in cases.items():
        old_times, new_times = [], []
        for _ in range(args.rounds):  # alternating: both meet the same state of the machine
            times, old_answers = _timed(old, inputs)
            old_times += times
            times, new_answers = _timed(new, inputs)
            new_times += times
            if old_answers != new_answers:
                raise SystemExit(f"{name}: the numpy network and SB3's predict disagree")
        medians[name] = statistics.median(old_times), statistics.median(new_times)

    calls = len(states) * args.rounds
    print(
        f"{args.task}: {len(states)} decisions of {args.episodes} test-set episodes, each timed {args.rounds} times "
        f"({calls} calls per cell); median microseconds per decision, torch on 1 thread"
    )
    print(f"{'':<24}{'old: SB3 predict':>18}{'new: numpy':>14}{'old / new':>12}")
    for name, (old, new) in medians.items():
        print(f"{name:<24}{old:>18.1f}{new:>14.1f}{old / new:>12.1f}")
    return 0


# the command line -----------------------------------------------------------------------------------------------


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = top.add_subparsers(dest="command", required=True)

    def command(run, name: str) -> argparse.ArgumentParser:
        text = inspect.cleandoc(run.__doc__)
        sub = commands.add_parser(
            name, help=text.split("\n\n")[0], description=text, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        sub.set_defaults(run=run)
        return sub

    c = command(env, "env")
    c.add_argument("tasks", nargs="*", default=None, help="default: every task")
    c.add_argument("--episodes", type=int, default=20)
    c.add_argument("--rounds", type=int, default=3)

    c = command(recording, "recording")
    c.add_argument("tasks", nargs="*", default=["cart_pendulum", "battery"])
    c.add_argument("--policy", action="append", default=None, metavar="SPEC", help="default: always and every:3")
    c.add_argument("--rounds", type=int, default=2)
    c.add_argument("--workers", type=int, default=2)

    c = command(training, "training")
    c.add_argument("task", nargs="?", default="cart_pendulum")
    c.add_argument("--policy", action="append", default=[], metavar="PATH", help="trained policy file(s) for 'end'")
    c.add_argument("--episodes", type=int, default=20, help="episodes per measurement (default 20)")
    c.add_argument("--workers", type=int, default=2)
    c.add_argument("--backend", choices=("local", "ray"), default="local")
    c.add_argument("--json", default=None, metavar="PATH")

    c = command(versus, "versus")
    c.add_argument("rev", help="the earlier commit (anything git rev-parse takes)")
    c.add_argument("tasks", nargs="*", default=["cart_pendulum", "battery"])
    c.add_argument("--episodes", type=int, default=5)
    c.add_argument("--rounds", type=int, default=3)

    c = command(lookahead, "lookahead")
    c.add_argument("--episodes", type=int, default=5)
    c.add_argument("--json", help="write the measurements here")
    c.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two --json files")

    c = command(sb3, "sb3")
    c.add_argument("--task", default="cart_pendulum")
    c.add_argument("--model", default="policies/cart_pendulum/balance/ppo.zip")
    c.add_argument("--episodes", type=int, default=20)
    c.add_argument("--rounds", type=int, default=5)
    return top


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    if args.command == "env" and not args.tasks:
        from etmpc.systems import names

        args.tasks = list(names())
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
