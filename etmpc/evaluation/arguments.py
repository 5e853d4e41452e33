"""What :func:`etmpc.evaluation.evaluate.evaluate` is given, checked before any work: its arguments with the
command line's messages (for a call from Python, which no parser checked), and its policies, specs parsed
and objects checked, each named once."""

from __future__ import annotations

import os
from pathlib import Path

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_inputs
from etmpc.evaluation.backends import BACKENDS
from etmpc.evaluation.inputs import check_shipped, run_inputs
from etmpc.loop.records import EpisodeSink
from etmpc.policies import parse_policy
from etmpc.policies.specs import names_a_kind
from etmpc.policies.user import Checked, checked
from etmpc.systems import SystemKey


def check_arguments(
    domain, policies, episodes, repeats, workers, seed, testset_path, progress, backend, address, record, recompute_price
) -> None:
    """What the command line's parser checks, checked for a call from Python, with the same messages
    (raises :class:`EtmpcError`)."""
    if not isinstance(domain, (str, SystemKey)):
        raise EtmpcError(f"task: a task name (str) is needed, got {type(domain).__name__} {domain!r}")
    check_policies(policies)
    if episodes is not None:
        checks.argument("episodes", lambda v: checks.at_least(checks.whole(v), 1), episodes)
    checks.argument("repeats", lambda v: checks.at_least(checks.whole(v), 1), repeats)
    if workers is not None:
        checks.argument("workers", checks.workers, workers)
    checks.argument("seed", checks.seed, seed)
    record = None if isinstance(record, EpisodeSink) else record  # an open recording: checked where it was opened
    for name, path in (("test_set", testset_path), ("record", record)):
        if path is not None and not isinstance(path, (str, os.PathLike)):
            raise EtmpcError(f"{name}: a file path is needed, got {type(path).__name__} {path!r}")
    if record is not None and Path(record).suffix != ".rrd":
        raise EtmpcError(f"record: {record} does not end in .rrd")
    if not isinstance(progress, bool):
        raise EtmpcError(f"progress: True or False, got {progress!r}")
    if backend not in BACKENDS:
        raise EtmpcError(f"backend: unknown backend {backend!r}: {' | '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise EtmpcError("--address needs --backend ray")


def check_policies(policies) -> None:
    """Raise :class:`EtmpcError` unless ``policies`` is a non-empty list (or tuple) of specs or objects."""
    if isinstance(policies, (str, bytes)) or not isinstance(policies, (list, tuple)):
        hint = f" (for one policy: [{policies!r}])" if isinstance(policies, str) else ""
        raise EtmpcError(f"policies: a list of policy specs or objects is needed, got {type(policies).__name__}{hint}")
    if not policies:
        raise EtmpcError("policies: the list is empty; give at least one policy (a spec such as 'every:3', or an object)")


def parse_policies(system, policies: list) -> dict:
    """``policies`` (specs and objects) as the policies ``system``'s loop plays, by spec: each spec
    parsed, each object checked; a bad one, or one named twice, raises :class:`EtmpcError`. A file a spec
    reads that is no regular file (a FIFO, which would hang the read; a device) is refused before any is read."""
    check_inputs(run_inputs(policies))
    parsed = {}
    for policy in policies:
        if isinstance(policy, str):
            check_shipped(policy)
            spec, policy = policy, parse_policy(policy, system)
        else:
            policy = checked(policy, levels=system.compute_levels)  # its answers checked as the task takes them
            assert isinstance(policy, Checked)  # checked() wraps every object it is given (its policy: the user's)
            spec = policy.spec
            if names_a_kind(spec) and not type(policy.policy).__module__.startswith("etmpc."):
                raise EtmpcError(
                    f"policy object {type(policy.policy).__name__} has the spec {spec!r}, a built-in policy's: "
                    "give it a name of its own, or the results would show its numbers as that policy's"
                )
        if spec in parsed:
            raise EtmpcError(f"policy {spec} is given twice")
        parsed[spec] = policy
    return parsed
