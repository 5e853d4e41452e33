"""One function per ``etmpc`` command: check what the options name, call the one function that does
the work, print what it wrote. Each command imports the floor it calls when it runs, so that
``etmpc --help`` does not load MuJoCo, Rerun and matplotlib."""

from __future__ import annotations

import sys
from pathlib import Path

from etmpc.cli import discriminate, figures, legacy, scoring, study, suite, training
from etmpc.cli.recording import file_of, recorded, viewer
from etmpc.cli.output import check_backend as _check_backend, distinct_policies as _distinct_policies, say as _say
from etmpc.common.errors import EtmpcError
from etmpc.common.wording import counted
from etmpc.common.progress import Progress
from etmpc.common.outputs import write_json


def check_run_outputs(outputs, directories=None, inputs=None) -> None:
    """:func:`etmpc.evaluation.inputs.check_run_outputs`, imported when a command runs (not for ``--help``)."""
    from etmpc.evaluation.inputs import check_run_outputs as check

    check(outputs, directories, inputs)


def run_inputs(policies, test_set=None) -> dict:
    from etmpc.evaluation.inputs import run_inputs as inputs

    return inputs(policies, test_set)


def _evaluate(args) -> None:
    from etmpc.evaluation.evaluate import evaluate, format_table
    from etmpc.systems import system_key
    from etmpc.views.recording import Recorder

    _check_backend(args)
    _distinct_policies(args.policy)
    if args.against is not None and args.against not in args.policy:
        raise EtmpcError(f"--against {args.against} is not one of the --policy given")
    check_run_outputs({"--json": args.json, "--record": file_of(args.record)}, inputs=run_inputs(args.policy, args.test_set))
    if args.test_set is not None and not Path(args.test_set).is_file():
        raise EtmpcError(f"test set {args.test_set} not found")
    key = system_key(args.task, args.price, args.options)  # the task at its price: one value from here to the objective
    with viewer(args) as live:  # --record URL, --spawn: a viewer, opened and checked before any work (a file: by evaluate)
        result = evaluate(
            key,
            args.policy,
            args.episodes,
            args.repeats,
            args.workers,
            args.seed,
            args.test_set,
            backend=args.backend,
            address=args.address,
            record=live or args.record,
            recorder=Recorder,
        )
    print(format_table(result))
    if args.against is not None:
        from etmpc.evaluation.compare import format_against

        print(format_against(result.to_json(), args.against))
    if args.record is not None or live is not None:
        print(recorded(args.record, live))
    if args.json is not None:
        write_json(args.json, result.to_json())
        print(f"wrote {args.json}")
    nonfinite = sum(s.nonfinite_episodes for s in result.summaries)
    if nonfinite:
        print(
            f"warning: {nonfinite} run(s) ended on a non-finite state or input and are excluded from the means", file=sys.stderr
        )


def _reproduce(args) -> None:
    from etmpc.experiments.reproduce import FULL, QUICK, reproduce
    from etmpc.evaluation.workers import default_workers

    from etmpc.systems import distinct

    tasks = None if args.task is None else distinct(args.task)
    _check_backend(args)
    out = args.out or Path("results") / ("reproduce-quick" if args.quick else "reproduce")
    check_run_outputs({}, {"--out": out})
    reproduce(
        out,
        QUICK if args.quick else FULL,
        args.workers or default_workers(),
        args.backend,
        args.address,
        domains=tasks,
        sweep=args.sweep,
    )
    print(f"wrote {out}/REPORT.md and {out}/results.json")


def _sweep(args) -> None:
    from etmpc.evaluation.workers import default_workers
    from etmpc.experiments.pareto import report_section
    from etmpc.experiments.sweep import check_directory, plan, sweep
    from etmpc.systems import folder_name

    settings = plan(args.task, args.prices, args.episodes, args.quick, args.options)  # names, prices, sizes, options checked
    _check_backend(args)
    out = args.out or Path("results") / ("sweep-quick" if args.quick else "sweep")
    check_run_outputs({}, {"--out": out})
    for task, chosen in settings.items():  # every directory checked before any work
        check_directory(out / folder_name(task), task, chosen)
    for task, chosen in settings.items():
        pareto = sweep(
            task, out / folder_name(task), chosen, args.workers or default_workers(), args.backend, args.address, say=_say
        )
        print("\n".join(report_section(pareto)))
        print(f"wrote {out / folder_name(task)}/pareto.json, pareto.png and SWEEP.md")


def _render(args) -> None:
    from etmpc.views.render import render_rollout
    from etmpc.systems import system_key
    from etmpc.views.video import check_display

    check_display()  # before any domain is imported: an on-screen backend warns without a display
    key = system_key(args.task, options=args.options)  # the task with its options, checked
    if args.out.suffix != ".mp4":
        raise EtmpcError(f"--out {args.out} does not end in .mp4")
    check_run_outputs({"--out": args.out, "--record": file_of(args.record)}, inputs=run_inputs([args.policy]))
    try:
        result = render_rollout(
            key, args.policy, args.episode, args.out, args.seed, args.width, args.height, args.fps, record=args.record
        )
    except ValueError as exc:
        raise EtmpcError(" ".join(str(exc).split())) from None
    print(
        f"wrote {result.path}: {result.frames} frames at {result.fps:g} fps, {counted(result.trajectory.recomputes, 'recompute')}"
    )
    if args.record is not None:
        print(f"wrote {args.record}" if file_of(args.record) else f"streamed the episode to {args.record}")


def _replay(args) -> None:
    from dataclasses import asdict

    from etmpc.views.replay import format_replay, replay_summary

    check_run_outputs({"--json": args.json}, inputs={"recording": args.recording})
    episodes = replay_summary(args.recording)
    print(format_replay(episodes, args.per_episode))
    if args.json is not None:
        write_json(args.json, {"recording": str(args.recording), "episodes": [asdict(e) for e in episodes]})
        print(f"wrote {args.json}")


def _bench(args) -> None:
    from etmpc.evaluation.bench import benched, format_bench, run_bench
    from etmpc.systems import check_name, names, system_key

    domains = args.task or list(names())
    for domain in domains:  # all names checked before any bench runs
        check_name(domain)
    keys = {domain: system_key(domain, options=args.options) for domain in domains}  # and every task's options
    check_run_outputs({"--json": args.json})
    for key in keys.values():  # and every task's system and test set, with the episodes asked
        benched(key, args.episodes)
    figures = {}
    # counted between the tasks' measurements, never inside one: the bar costs no measured time
    with Progress(len(domains), unit="tasks") as bar:
        for domain in domains:
            figures[domain] = run_bench(keys[domain], episodes=args.episodes, references=not args.no_reference)
            bar.result(format_bench(figures[domain]))
            bar.update()
    if args.json is not None:
        write_json(args.json, figures)
        print(f"wrote {args.json}")


def _verify(args) -> None:
    from etmpc.evaluation.verify import verify

    verdict = verify(args.card, args.sample, args.seed, args.workers, progress=True, allow_code=args.allow_code, say=_say)
    if verdict.caution is not None:
        print(f"note: {verdict.caution}")
    for line in verdict.mismatches:
        print(line)
    if not verdict.verified:
        raise EtmpcError(f"card {args.card} does not verify: {len(verdict.mismatches)} mismatch(es), listed above")
    print(
        f"verified: card {args.card}: {verdict.rows} rows; every number it states follows from its episodes, "
        f"and {counted(verdict.replayed, 'episode')} replayed give the card's numbers bit for bit"
        + (f"; the references of {', '.join(verdict.rebuilt)} (scored with options) rebuilt in full" if verdict.rebuilt else "")
    )


def _testset(args) -> None:
    from etmpc.evaluation.testsets import draw
    from etmpc.systems import system_key

    check_run_outputs({"--out": args.out})
    key = system_key(args.task, options=args.options)  # a world's options (its disturbances) change the draws
    digest = draw(key.make(), args.seed, args.episodes, args.out)
    print(
        f"wrote {args.out} and {args.out}.sha256 ({counted(args.episodes, 'episode')} of {key}, seed {args.seed}, "
        f"sha256 {digest}); use it with --test-set {args.out}" + (" and the same options" if key.options else "")
    )


def _robustness(args) -> None:
    from etmpc.experiments.robustness import check_out, parse_vary, robustness, write

    option, values = parse_vary(args.vary)
    _distinct_policies(args.policy)
    check_out(args.out, args.policy)  # a directory, of no one else's files and none the policies read
    document = robustness(
        args.task, option, values, args.policy, args.against, args.episodes, args.workers, args.options, say=_say
    )
    for path in write(document, args.out):
        print(f"wrote {path}")


COMMANDS = {
    "evaluate": _evaluate,
    "score": scoring.run,
    "train": training.run,
    "train-self": legacy.run_self,
    "reproduce": _reproduce,
    "sweep": _sweep,
    "render": _render,
    "replay": _replay,
    "bench": _bench,
    "testset": _testset,
    "verify": _verify,
    "robustness": _robustness,
    "options": suite.run_options,
    "tasks": suite.run,
    "discriminate": discriminate.run,
    "figure": figures.run,
    "study": study.run,
}
