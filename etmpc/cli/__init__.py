"""The ``etmpc`` command: ``reproduce``, ``evaluate``, ``sweep``, ``train``, ``render``, ``replay`` and ``bench``.

Bad input (unknown task or policy, bad numbers, missing or corrupt files) prints one line on
stderr and exits with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
from pathlib import Path

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_outputs, write_json

# MuJoCo's OpenGL backends on Linux (mujoco/rendering/classic/gl_context.py): anything else makes
# importing dm-control fail, so the command checks it before importing anything that renders.
GL_BACKENDS = ("egl", "osmesa", "glfw", "glx", "enable", "enabled", "on", "true", "1", "",
               "disable", "disabled", "off", "false", "0")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit code 2
        raise EtmpcError(message)


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _positive_int(text: str) -> int:
    value = _whole(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


MAX_WORKERS = 512
MAX_SEED = 2**63 - 1
MAX_FPS = 1000.0


def _workers(text: str) -> int:
    value = _positive_int(text)
    if value > MAX_WORKERS:
        raise argparse.ArgumentTypeError(f"at most {MAX_WORKERS} worker processes, got {value}")
    return value


def _seed(text: str) -> int:
    value = _whole(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"a seed is a whole number in 0..2**63-1, got {value}")
    return value


def _index(text: str) -> int:
    value = _whole(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _fps(text: str) -> float:
    value = _number(text)
    if not (math.isfinite(value) and 0 < value <= MAX_FPS):
        raise argparse.ArgumentTypeError(f"frames per second must be in (0, {MAX_FPS:g}], got {text}")
    return value


def _price(text: str) -> float:
    value = _number(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"a price of a computation is a finite number >= 0, got {text}")
    return value


def _prices(text: str) -> tuple[float, ...]:
    return tuple(_price(part.strip()) for part in text.split(","))


def _json_path(text: str) -> Path:
    path = Path(text)
    if path.exists() and path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory, not a file")
    return path


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("etmpc")
    except PackageNotFoundError:
        return "(not installed)"


def _check_gl() -> None:
    backend = os.environ.get("MUJOCO_GL", "")
    if backend.lower().strip() not in GL_BACKENDS:
        raise EtmpcError(f"MUJOCO_GL={backend} is not an OpenGL backend MuJoCo knows: use egl (headless, the default), "
                         "osmesa (software) or glfw (with a display)")


def build_parser() -> argparse.ArgumentParser:
    from etmpc.learning.gpomdp import BASELINES
    from etmpc.policies.learned import DEFAULT_FEATURES, FEATURE_SETS
    from etmpc.systems import names
    from etmpc.learning.train import ALGORITHMS

    tasks = " | ".join(names())
    parser = _Parser(prog="etmpc", description="Event-triggered MPC benchmark.")
    parser.add_argument("--version", action="version", version=f"etmpc {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser("evaluate", help="compare recomputation policies on a stored test set")
    ev.add_argument("task", help=f"system to evaluate: {tasks}")
    ev.add_argument("--policy", action="append", required=True, metavar="SPEC",
                    help="always | never | every:T | threshold:X | rl:PATH | self:PATH | rollout:BASE[:K[:H]] | "
                         "oracle:BASE (an upper bound, not a policy) (repeatable)")
    ev.add_argument("--episodes", type=_positive_int, default=None, help="first N test-set episodes (default: all)")
    ev.add_argument("--repeats", type=_positive_int, default=1, help="passes over the test set (for stochastic policies)")
    ev.add_argument("--workers", type=_workers, default=None, help="worker processes (default: one per core)")
    ev.add_argument("--seed", type=_seed, default=0, help="seed of the policies' own randomness")
    ev.add_argument("--price", type=_price, default=None, metavar="P",
                    help="price of a computation in the objective (default: the system's, 5e-5 for the cart "
                         "pendulum, 0 for the battery, whose computer draws eta_c from the battery)")
    ev.add_argument("--test-set", default=None, metavar="PATH", help="test set file (default: the stored one)")
    ev.add_argument("--json", type=_json_path, default=None, metavar="PATH", help="write the results as JSON")
    ev.add_argument("--record", type=_rrd_path, default=None, metavar="PATH.rrd",
                    help="write every episode into a Rerun recording (open it with `rerun PATH.rrd`)")
    _backend_arguments(ev)

    tr = sub.add_parser("train", help="train the learned recomputation policy with GPOMDP over several seeds")
    tr.add_argument("task", help=f"system to train on: {tasks}")
    tr.add_argument("--seeds", default="0-4", help="seeds: a range 0-4 or a list 0,2,5 (default 0-4)")
    tr.add_argument("--episodes", type=_positive_int, default=1500, help="training episodes per seed (default 1500)")
    tr.add_argument("--eval-every", type=_positive_int, default=150, help="evaluate on the test set every N episodes (default 150)")
    tr.add_argument("--eval-episodes", type=_positive_int, default=None, help="first N test-set episodes per evaluation (default: all)")
    tr.add_argument("--out", type=Path, required=True, metavar="DIR", help="run directory: checkpoint, policies, curve")
    tr.add_argument("--workers", type=_workers, default=None, help="worker processes (default: one per core)")
    _backend_arguments(tr)
    tr.add_argument("--resume", action="store_true", help="continue the run in DIR from its last checkpoint")
    tr.add_argument("--record", type=_index, default=0, metavar="N",
                    help="record the first N test-set episodes of each seed at every evaluation, "
                         "into DIR/recordings/eval_<episodes>.rrd (default 0: none)")
    tr.add_argument("--baseline", choices=BASELINES, default="none",
                    help="GPOMDP baseline: none (the paper, default), mean (per step index), state (linear value function)")
    tr.add_argument("--learning-rate", type=float, default=0.05, help="GPOMDP's alpha (default 0.05)")
    tr.add_argument("--discount", type=float, default=0.975, help="GPOMDP's gamma (default 0.975)")
    tr.add_argument("--algorithm", choices=ALGORITHMS, default="dpi",
                    help="dpi (direct policy iteration: rollout-labelled classification, --eval-every episodes per "
                         "iteration; default) or gpomdp (the paper's policy gradient)")
    tr.add_argument("--features", choices=FEATURE_SETS, default=DEFAULT_FEATURES,
                    help="the policy's features: error (prediction error, its square, the plan's age and, for the "
                         "battery, prices and production now and as planned; default) or paper ([x_i, x_k, i-k] and squares)")
    tr.add_argument("--futures", type=_positive_int, default=None, metavar="K", help="DPI: sampled futures per labelled decision (default 4)")
    tr.add_argument("--horizon", type=_positive_int, default=None, metavar="H", help="DPI: steps simulated ahead (default 20)")
    tr.add_argument("--labels", type=_positive_int, default=None, metavar="D", help="DPI: decisions labelled per episode (default 25)")
    tr.add_argument("--price", type=_price, default=None, metavar="P",
                    help="train for this price of a computation (default: the system's; see evaluate --price)")
    tr.add_argument("--validation-episodes", type=_positive_int, default=50,
                    help="training-distribution episodes that choose selected.json among the seeds (default 50)")

    ts = sub.add_parser("train-self", help="train a self-triggering policy (self:PATH): at each solve, how long to keep the plan")
    ts.add_argument("task", help=f"system to train on: {tasks}")
    ts.add_argument("--out", type=_json_path, required=True, metavar="FILE", help="the policy file to write (use it as self:FILE)")
    ts.add_argument("--price", type=_price, default=None, metavar="P",
                    help="train for this price of a computation (default: the system's; see evaluate --price)")
    ts.add_argument("--episodes", type=_positive_int, default=40, help="labelled training episodes (default 40)")
    ts.add_argument("--solves", type=_positive_int, default=8, help="labelled solves per episode (default 8)")
    ts.add_argument("--futures", type=_positive_int, default=2, metavar="K", help="sampled futures per labelled solve (default 2)")
    ts.add_argument("--validation-episodes", type=_positive_int, default=20,
                    help="training-distribution episodes that choose among the fits and the base (default 20)")
    ts.add_argument("--workers", type=_workers, default=None, help="worker processes (default: one per core)")
    _backend_arguments(ts)

    re_ = sub.add_parser("reproduce", help="the paper's experiments on both systems, with REPORT.md and results.json")
    re_.add_argument("--quick", action="store_true", help="the same steps at small sizes (a few minutes)")
    re_.add_argument("--sweep", action="store_true",
                     help="also sweep the price of a computation (etmpc sweep) and answer the equal-rate question in the report")
    re_.add_argument("--out", type=Path, default=None, metavar="DIR",
                     help="run directory (default results/reproduce, or results/reproduce-quick with --quick)")
    re_.add_argument("--workers", type=_workers, default=None, help="worker processes (default: one per core)")
    _backend_arguments(re_)

    sw = sub.add_parser("sweep", help="the trade-off curve over prices of a computation: pareto.json, pareto.png, SWEEP.md")
    sw.add_argument("task", nargs="*", help=f"systems to sweep: {tasks} (default: every system)")
    sw.add_argument("--prices", type=_prices, default=None, metavar="P1,P2,...",
                    help="prices of a computation (default: a log grid per system, up to where `never` wins)")
    sw.add_argument("--episodes", type=_positive_int, default=None,
                    help="first N test-set episodes for every policy (default 20, 3 with --quick)")
    sw.add_argument("--quick", action="store_true", help="a smoke run: 3 episodes, half the thresholds, rollouts K=2 H=10")
    sw.add_argument("--out", type=Path, default=None, metavar="DIR",
                    help="run directory, a folder per system (default results/sweep, or results/sweep-quick with --quick)")
    sw.add_argument("--workers", type=_workers, default=None, help="worker processes (default: one per core)")
    _backend_arguments(sw)

    rn = sub.add_parser("render", help="render one test-set episode headless to an MP4 video (cart_pendulum)")
    rn.add_argument("task", help="system to render: cart_pendulum (the battery has no 3-D scene)")
    rn.add_argument("--policy", required=True, metavar="SPEC", help="always | never | every:T | threshold:X | rl:PATH | self:PATH")
    rn.add_argument("--episode", type=_index, default=0, help="test-set episode (default 0)")
    rn.add_argument("--out", type=Path, required=True, metavar="FILE.mp4")
    rn.add_argument("--seed", type=_seed, default=0, help="seed of the policy's own randomness, as in evaluate")
    rn.add_argument("--width", type=_positive_int, default=640)
    rn.add_argument("--height", type=_positive_int, default=480)
    rn.add_argument("--fps", type=_fps, default=None, help="frames per second (default: one frame per control interval)")
    rn.add_argument("--record", type=_rrd_path, default=None, metavar="PATH.rrd",
                    help="also write the episode, frames included, into a Rerun recording")

    rp = sub.add_parser("replay", help="summarise a Rerun recording: objective, recomputes, prediction errors")
    rp.add_argument("recording", type=Path, metavar="PATH.rrd")
    rp.add_argument("--per-episode", action="store_true", help="one line per episode, not only per policy")
    rp.add_argument("--json", type=_json_path, default=None, metavar="PATH", help="write every episode's figures as JSON")

    be = sub.add_parser("bench", help="time the MPC solve, the rest of a step and whole episodes")
    be.add_argument("tasks", nargs="*", metavar="TASK", help=f"systems to bench (default: all: {tasks})")
    be.add_argument("--episodes", type=_positive_int, default=10, help="test-set episodes per measurement")
    be.add_argument("--json", type=_json_path, default=None, metavar="PATH", help="write the figures as JSON")
    be.add_argument("--no-reference", action="store_true",
                    help="skip the reference solvers (do-mpc for cart_pendulum, scipy linprog for battery)")
    return parser


def _rrd_path(text: str) -> Path:
    path = _json_path(text)
    if path.suffix != ".rrd":
        raise argparse.ArgumentTypeError(f"{text} does not end in .rrd")
    return path


def _backend_arguments(parser: argparse.ArgumentParser) -> None:
    from etmpc.evaluation.workers import BACKENDS

    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="where the work runs: local processes, or Ray (the 'ray' extra); results are the same")
    parser.add_argument("--address", default=None, metavar="ADDR",
                        help="Ray cluster to join, e.g. auto or ray://HOST:10001 (with --backend ray; "
                             "default: start a local Ray instance of --workers CPUs)")


def _check_backend(args) -> None:
    if args.address is not None and args.backend != "ray":
        raise EtmpcError("--address needs --backend ray")


def _say(line: str) -> None:
    """Progress of a long stage, on stderr (stdout keeps the results)."""
    print(line, file=sys.stderr, flush=True)


def _distinct_policies(specs: list[str]) -> None:
    seen = set()
    for spec in specs:
        if spec in seen:
            raise EtmpcError(f"--policy {spec} is given twice")
        seen.add(spec)


def _evaluate(args) -> None:
    from etmpc.evaluation.evaluate import evaluate, format_table

    _check_backend(args)
    _distinct_policies(args.policy)
    if args.test_set is not None and not Path(args.test_set).is_file():
        raise EtmpcError(f"test set {args.test_set} not found")
    check_outputs({"--json": args.json, "--record": args.record}, inputs={"--test-set": args.test_set})
    result = evaluate(args.task, args.policy, args.episodes, args.repeats, args.workers, args.seed, args.test_set,
                      backend=args.backend, address=args.address, record=args.record, recompute_price=args.price)
    print(format_table(result))
    if args.record is not None:
        print(f"wrote {args.record} (open it with: rerun {args.record}; summarise it with: etmpc replay {args.record})")
    if args.json is not None:
        write_json(args.json, result.to_json())
        print(f"wrote {args.json}")
    nonfinite = sum(s.nonfinite_episodes for s in result.summaries)
    if nonfinite:
        print(f"warning: {nonfinite} run(s) ended on a non-finite state and are excluded from the means", file=sys.stderr)


def _train(args) -> None:
    from etmpc.learning.dpi import Settings as DpiSettings
    from etmpc.learning.gpomdp import Settings
    from etmpc.learning.train import TrainConfig, format_summary, parse_seeds, train
    from etmpc.systems import check_name
    from etmpc.evaluation.workers import default_workers

    check_name(args.task)
    _check_backend(args)
    check_outputs({}, {"--out": args.out})
    dpi_options = {"futures": args.futures, "horizon": args.horizon, "states_per_episode": args.labels}
    if args.algorithm != "dpi" and any(v is not None for v in dpi_options.values()):
        raise EtmpcError("--futures, --horizon and --labels are DPI's settings: add --algorithm dpi")
    try:
        settings = Settings(args.discount, args.learning_rate, args.baseline)
        dpi_settings = DpiSettings(**{k: v for k, v in dpi_options.items() if v is not None})
    except ValueError as exc:
        raise EtmpcError(str(exc)) from None
    config = TrainConfig(args.task, parse_seeds(args.seeds), args.episodes, args.eval_every, args.eval_episodes, gpomdp=settings,
                         features=args.features, algorithm=args.algorithm, dpi=dpi_settings,
                         validation_episodes=args.validation_episodes, recompute_price=args.price)
    state = train(config, args.out, args.workers or default_workers(), args.resume, args.backend, args.address,
                  record_episodes=args.record)
    print(format_summary(state))
    print(f"wrote {args.out}/selected.json, curve.json, curve.png, checkpoint.json and seed*/best.json, last.json")


def _train_self(args) -> None:
    from etmpc.learning.selftrigger import SelfSettings, train_self
    from etmpc.systems import check_name, system_key
    from etmpc.evaluation.workers import default_workers

    check_name(args.task)
    _check_backend(args)
    check_outputs({"--out": args.out})
    settings = SelfSettings(episodes=args.episodes, solves_per_episode=args.solves, futures=args.futures,
                            validation_episodes=args.validation_episodes)
    train_self(system_key(args.task, args.price), args.out, settings, args.workers or default_workers(), args.backend,
               args.address, say=_say)
    print(f"wrote {args.out} (evaluate it with: etmpc evaluate {args.task} --policy self:{args.out}"
          f"{'' if args.price is None else f' --price {args.price:g}'})")


def _reproduce(args) -> None:
    from etmpc.experiments.reproduce import FULL, QUICK, reproduce
    from etmpc.evaluation.workers import default_workers

    _check_backend(args)
    out = args.out or Path("results") / ("reproduce-quick" if args.quick else "reproduce")
    check_outputs({}, {"--out": out})
    reproduce(out, QUICK if args.quick else FULL, args.workers or default_workers(), args.backend, args.address,
              sweep=args.sweep)
    print(f"wrote {out}/REPORT.md and {out}/results.json")


def _sweep(args) -> None:
    from etmpc.experiments.pareto import report_section
    from etmpc.experiments.sweep import SweepSettings, check_directory, sweep
    from etmpc.systems import check_name, make_system, names
    from etmpc.evaluation.testsets import default_path, load
    from etmpc.evaluation.workers import default_workers

    args.task = args.task or list(names())
    for task in args.task:
        check_name(task)
    if len(set(args.task)) != len(args.task):
        raise EtmpcError("a task is given twice")
    _check_backend(args)
    out = args.out or Path("results") / ("sweep-quick" if args.quick else "sweep")
    settings = {task: SweepSettings.default(task, args.prices, args.episodes, args.quick) for task in args.task}
    for task, chosen in settings.items():
        system = make_system(task)
        stored = load(default_path(system.domain, system.task), system.domain, system.task)
        if chosen.episodes > stored.episodes:
            raise EtmpcError(f"--episodes must be in 1..{stored.episodes} for the {task} test set, got {chosen.episodes}")
    check_outputs({}, {"--out": out})
    for task in args.task:  # every directory checked before any work
        check_directory(out / task, task, settings[task])
    for task in args.task:
        pareto = sweep(task, out / task, settings[task], args.workers or default_workers(), args.backend, args.address,
                       say=_say)
        print("\n".join(report_section(pareto)))
        print(f"wrote {out / task}/pareto.json, pareto.png and SWEEP.md")


def _render(args) -> None:
    from etmpc.evaluation.render import render_rollout
    from etmpc.systems import check_name

    check_name(args.task)
    if args.out.suffix != ".mp4":
        raise EtmpcError(f"--out {args.out} does not end in .mp4")
    check_outputs({"--out": args.out, "--record": args.record})
    try:
        result = render_rollout(args.task, args.policy, args.episode, args.out, args.seed, args.width, args.height,
                                args.fps, record=args.record)
    except ValueError as exc:
        raise EtmpcError(str(exc)) from None
    print(f"wrote {result.path}: {result.frames} frames at {result.fps:g} fps, {result.trajectory.recomputes} recomputes")
    if args.record is not None:
        print(f"wrote {args.record}")


def _replay(args) -> None:
    from dataclasses import asdict

    from etmpc.views.replay import format_replay, replay_summary

    check_outputs({"--json": args.json}, inputs={"recording": args.recording})
    episodes = replay_summary(args.recording)
    print(format_replay(episodes, args.per_episode))
    if args.json is not None:
        write_json(args.json, {"recording": str(args.recording), "episodes": [asdict(e) for e in episodes]})
        print(f"wrote {args.json}")


def _bench(args) -> None:
    from etmpc.evaluation.bench import format_bench, run_bench
    from etmpc.systems import check_name, names

    domains = args.tasks or list(names())
    for domain in domains:  # all names checked before any bench runs
        check_name(domain)
    check_outputs({"--json": args.json})
    figures = {}
    for domain in domains:
        figures[domain] = run_bench(domain, episodes=args.episodes, references=not args.no_reference)
        print(format_bench(figures[domain]), flush=True)
    if args.json is not None:
        write_json(args.json, figures)
        print(f"wrote {args.json}")


class _Terminated(BaseException):
    """SIGTERM, turned into an orderly stop: workers shut down, partial files removed."""


def _terminate(signum, frame):
    raise _Terminated


def main(argv: list[str] | None = None) -> int:
    """Run the command; returns the exit code: 0, 2 for any error (one line on stderr), 130 for
    Ctrl-C and 143 for SIGTERM (each also one line)."""
    # Rerun's own log lines (its file writer's errors) stay off stderr: a failure to write a
    # recording is reported as one line by etmpc itself. Set RUST_LOG to see them.
    os.environ.setdefault("RUST_LOG", "off")
    # The numerical libraries run single-threaded (the work is spread over processes instead), so
    # their sums do not depend on how many cores the machine has; set these yourself to override.
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    try:
        _check_gl()
        args = build_parser().parse_args(argv)
        {"evaluate": _evaluate, "train": _train, "reproduce": _reproduce, "render": _render, "replay": _replay,
         "bench": _bench, "sweep": _sweep, "train-self": _train_self}[args.command](args)
    except EtmpcError as exc:
        print(f"etmpc: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the machine refused (a full disk, a vanished directory): one line, no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"etmpc: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("etmpc: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("etmpc: terminated", file=sys.stderr)
        return 143
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    return 0

