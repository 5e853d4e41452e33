"""The ``etmpc`` command: ``reproduce``, ``evaluate``, ``train``, ``render``, ``replay`` and ``bench``.

Bad input (unknown task or policy, bad numbers, missing or corrupt files) prints one line on
stderr and exits with code 2, without a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from etmpc.errors import EtmpcError
from etmpc.gpomdp import BASELINES
from etmpc.learned import DEFAULT_FEATURES, FEATURE_SETS
from etmpc.train import ALGORITHMS
from etmpc.systems import check_name, names
from etmpc.workers import BACKENDS


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit code 2
        raise EtmpcError(message)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _json_path(text: str) -> Path:
    path = Path(text)
    if path.exists() and path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory, not a file")
    return path


def build_parser() -> argparse.ArgumentParser:
    tasks = " | ".join(names())
    parser = _Parser(prog="etmpc", description="Event-triggered MPC benchmark.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser("evaluate", help="compare recomputation policies on a stored test set")
    ev.add_argument("task", help=f"system to evaluate: {tasks}")
    ev.add_argument("--policy", action="append", required=True, metavar="SPEC",
                    help="always | never | every:T | threshold:X | rl:PATH | rollout:BASE[:K[:H]] | "
                         "oracle:BASE (an upper bound, not a policy) (repeatable)")
    ev.add_argument("--episodes", type=_positive_int, default=None, help="first N test-set episodes (default: all)")
    ev.add_argument("--repeats", type=_positive_int, default=1, help="passes over the test set (for stochastic policies)")
    ev.add_argument("--workers", type=_positive_int, default=None, help="worker processes (default: one per core)")
    ev.add_argument("--seed", type=int, default=0, help="seed of the policies' own randomness")
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
    tr.add_argument("--workers", type=_positive_int, default=None, help="worker processes (default: one per core)")
    _backend_arguments(tr)
    tr.add_argument("--resume", action="store_true", help="continue the run in DIR from its last checkpoint")
    tr.add_argument("--record", type=int, default=0, metavar="N",
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
    tr.add_argument("--validation-episodes", type=_positive_int, default=50,
                    help="training-distribution episodes that choose selected.json among the seeds (default 50)")

    re_ = sub.add_parser("reproduce", help="the paper's experiments on both systems, with REPORT.md and results.json")
    re_.add_argument("--quick", action="store_true", help="the same steps at small sizes (a few minutes)")
    re_.add_argument("--out", type=Path, default=None, metavar="DIR",
                     help="run directory (default results/reproduce, or results/reproduce-quick with --quick)")
    re_.add_argument("--workers", type=_positive_int, default=None, help="worker processes (default: one per core)")
    _backend_arguments(re_)

    rn = sub.add_parser("render", help="render one test-set episode headless to an MP4 video (cart_pendulum)")
    rn.add_argument("task", help="system to render: cart_pendulum (the battery has no 3-D scene)")
    rn.add_argument("--policy", required=True, metavar="SPEC", help="always | never | every:T | threshold:X | rl:PATH")
    rn.add_argument("--episode", type=int, default=0, help="test-set episode (default 0)")
    rn.add_argument("--out", type=Path, required=True, metavar="FILE.mp4")
    rn.add_argument("--seed", type=int, default=0, help="seed of the policy's own randomness, as in evaluate")
    rn.add_argument("--width", type=_positive_int, default=640)
    rn.add_argument("--height", type=_positive_int, default=480)
    rn.add_argument("--fps", type=float, default=None, help="frames per second (default: one frame per control interval)")
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
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="where the work runs: local processes, or Ray (the 'ray' extra); results are the same")
    parser.add_argument("--address", default=None, metavar="ADDR",
                        help="Ray cluster to join, e.g. auto or ray://HOST:10001 (with --backend ray; "
                             "default: start a local Ray instance of --workers CPUs)")


def _check_backend(args) -> None:
    if args.address is not None and args.backend != "ray":
        raise EtmpcError("--address needs --backend ray")


def _write_json(path: Path, data: dict) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=2) + "\n")
    except OSError as exc:
        raise EtmpcError(f"cannot write {path}: {exc.strerror}") from None


def _evaluate(args) -> None:
    from etmpc.evaluate import evaluate, format_table

    _check_backend(args)
    if args.test_set is not None and not Path(args.test_set).is_file():
        raise EtmpcError(f"test set {args.test_set} not found")
    result = evaluate(args.task, args.policy, args.episodes, args.repeats, args.workers, args.seed, args.test_set,
                      backend=args.backend, address=args.address, record=args.record)
    print(format_table(result))
    if args.record is not None:
        print(f"wrote {args.record} (open it with: rerun {args.record}; summarise it with: etmpc replay {args.record})")
    if args.json is not None:
        _write_json(args.json, result.to_json())
        print(f"wrote {args.json}")
    nonfinite = sum(s.nonfinite_episodes for s in result.summaries)
    if nonfinite:
        print(f"warning: {nonfinite} run(s) ended on a non-finite state and are excluded from the means", file=sys.stderr)


def _train(args) -> None:
    from etmpc.dpi import Settings as DpiSettings
    from etmpc.gpomdp import Settings
    from etmpc.train import TrainConfig, format_summary, parse_seeds, train
    from etmpc.workers import default_workers

    check_name(args.task)
    _check_backend(args)
    if args.out.exists() and not args.out.is_dir():
        raise EtmpcError(f"--out {args.out} exists and is not a directory")
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
                         validation_episodes=args.validation_episodes)
    state = train(config, args.out, args.workers or default_workers(), args.resume, args.backend, args.address,
                  record_episodes=args.record)
    print(format_summary(state))
    print(f"wrote {args.out}/selected.json, curve.json, curve.png, checkpoint.json and seed*/best.json, last.json")


def _reproduce(args) -> None:
    from etmpc.reproduce import FULL, QUICK, reproduce
    from etmpc.workers import default_workers

    _check_backend(args)
    out = args.out or Path("results") / ("reproduce-quick" if args.quick else "reproduce")
    if out.exists() and not out.is_dir():
        raise EtmpcError(f"--out {out} exists and is not a directory")
    reproduce(out, QUICK if args.quick else FULL, args.workers or default_workers(), args.backend, args.address)
    print(f"wrote {out}/REPORT.md and {out}/results.json")


def _render(args) -> None:
    from etmpc.render import render_rollout

    check_name(args.task)
    if args.out.suffix != ".mp4":
        raise EtmpcError(f"--out {args.out} does not end in .mp4")
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

    from etmpc.recording import format_replay, replay_summary

    episodes = replay_summary(args.recording)
    print(format_replay(episodes, args.per_episode))
    if args.json is not None:
        _write_json(args.json, {"recording": str(args.recording), "episodes": [asdict(e) for e in episodes]})
        print(f"wrote {args.json}")


def _bench(args) -> None:
    from etmpc.bench import format_bench, run_bench

    domains = args.tasks or list(names())
    for domain in domains:  # all names checked before any bench runs
        check_name(domain)
    figures = {}
    for domain in domains:
        figures[domain] = run_bench(domain, episodes=args.episodes, references=not args.no_reference)
        print(format_bench(figures[domain]), flush=True)
    if args.json is not None:
        _write_json(args.json, figures)
        print(f"wrote {args.json}")


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        {"evaluate": _evaluate, "train": _train, "reproduce": _reproduce, "render": _render, "replay": _replay,
         "bench": _bench}[args.command](args)
    except EtmpcError as exc:
        print(f"etmpc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("etmpc: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
