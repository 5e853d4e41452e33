"""Test sets: episodes whose random variables are all drawn in advance and stored.

A test set is one ``.npz`` file, ``tasks/<domain>/<task>/testset.npz``, with a ``.sha256`` file beside it. Each
named array has the episode index as its first axis; ``meta`` holds a JSON description (task,
seed, generator). The file is written with fixed zip timestamps so that regenerating it from its
seed (``etmpc testset --task TASK --seed S --out FILE``; each domain's ``TEST_SET_SEEDS`` holds its stored sets' seeds) gives
the same bytes, hence the same checksum.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.documents import loads
from etmpc.common.frozen import readonly
from etmpc.common.errors import EtmpcError, TestSetError
from etmpc.common.outputs import check_outputs, write_bytes
from etmpc.common.progress import Progress
from etmpc.systems import canonical, spec, stored_seed

FORMAT_VERSION = 1
STORED_EPISODES = 100
_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)


def default_path(domain: str, task: str) -> Path:
    """The stored test set of ``domain/task``, in its domain's data folder (:func:`etmpc.systems.data_dir`):
    ``etmpc testset --task TASK --seed SEED --episodes 100``, SEED its domain's ``TEST_SET_SEEDS[task]``
    (tests/evaluation/test_testset.py regenerates each bit for bit)."""
    return spec(f"{domain}/{task}").data_file("testset.npz")


def check_options_act(key, test_set: str | Path | None = None, takes_test_set: bool = True) -> None:
    """Refuse, in one line and before any work, options of ``key`` (a :class:`~etmpc.systems.SystemKey`) that
    cannot change a run on the stored test set (``test_set`` None, or the stored file named): those declared
    ``draws`` (:func:`etmpc.systems.options.drawn_only`) act only when episodes are drawn, and the stored
    episodes are replayed as they were drawn, so the run would be the task's own under another name. The line
    says how to draw a test set where they act, and where to play it (``takes_test_set``: the caller takes one;
    else evaluate and score do). Every command and function that plays a test set with options
    calls this one check (evaluate, score, robustness, render, bench, discriminate, figure, sweep, and the
    Gymnasium environment's test episodes); what draws its own episodes (testset, the learners) does not."""
    from etmpc.systems.base import system_type
    from etmpc.systems.options import drawn_only, shown

    if not key.options:
        return
    found = spec(key.task)
    if test_set is not None and Path(test_set).resolve() != default_path(found.domain, found.task).resolve():
        return  # a test set of the caller's: drawn with the options, we trust, as etmpc testset says
    cls = system_type(key.task)
    inert = drawn_only(cls.Config(), key.options)
    if inert:
        out, it = f"{found.slug}.npz", "it acts" if len(inert) == 1 else "they act"
        raise EtmpcError(
            f"option{'s' * (len(inert) > 1)} {', '.join(inert)}: {it} only on newly drawn episodes, not on the stored test "
            f"set of {key.task} (replayed as drawn): draw a test set where {it} with 'etmpc testset --task {key.task} "
            f"{shown(key.options)} --seed 1 --out {out}', then {_play_it(out, takes_test_set)}"
        )


def _play_it(out: str, takes_test_set: bool) -> str:
    if takes_test_set:
        return f"give --test-set {out} (test_set= in Python)"
    return f"play it with etmpc evaluate or score --test-set {out} (this command plays the stored test set only)"


def episode_generators(seed: int, episodes: int) -> list[np.random.Generator]:
    """One independent generator per episode, spawned from the test set's seed."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(episodes)]


def sha256_of(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def encode(arrays: dict[str, np.ndarray], meta: dict) -> bytes:
    """Deterministic ``.npz`` bytes (sorted names, fixed timestamps) readable by ``np.load``."""
    buffer = io.BytesIO()
    members = dict(arrays, meta=np.array(json.dumps(meta, sort_keys=True)))
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(members):
            payload = io.BytesIO()
            np.lib.format.write_array(payload, np.ascontiguousarray(members[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, payload.getvalue())
    return buffer.getvalue()


def write(path: Path, arrays: dict[str, np.ndarray], meta: dict) -> str:
    """Write the test set and its checksum file, each atomically; returns the sha256."""
    data = encode(arrays, meta)
    digest = hashlib.sha256(data).hexdigest()
    write_bytes(Path(path), data)
    write_bytes(checksum_path(Path(path)), f"{digest}  {Path(path).name}\n".encode())
    return digest


def checksum_path(path: Path) -> Path:
    return path.with_name(path.name + ".sha256")


@dataclass(frozen=True)
class TestSet:
    __test__ = False  # not a pytest test class

    path: Path
    sha256: str
    meta: dict
    arrays: dict[str, np.ndarray]

    @property
    def episodes(self) -> int:
        return int(self.meta["episodes"])

    def episode_arrays(self, index: int) -> dict[str, np.ndarray]:
        if not 0 <= index < self.episodes:
            raise TestSetError(f"episode {index} is out of range: the test set has {self.episodes} (0..{self.episodes - 1})")
        return {name: values[index] for name, values in self.arrays.items()}

    def check_playable(self, system, task) -> None:
        """Raise :class:`TestSetError` unless every episode is one ``task`` (of ``system``) can
        play: the arrays it needs, of the shapes it needs, every value within the task's ranges
        (``EpisodeTask.check_stored``); the error names the episode and the field."""
        for index in range(self.episodes):
            try:
                task.check_stored(system.episode_from_arrays(self.episode_arrays(index)))
            except KeyError as exc:
                raise TestSetError(f"test set {self.path} has no array {exc}") from None
            except (ValueError, TypeError) as exc:
                raise TestSetError(f"test set {self.path}, episode {index}: {exc}") from None


def load(path: str | Path, domain: str, task: str) -> TestSet:
    """Load and verify a test set; any problem raises :class:`TestSetError` with what to do.

    Beyond its checksum (which only says the file is the one its ``.sha256`` describes), the
    contents are checked: ``meta`` names the task and the number of episodes, and every array has
    one row per episode. Whether each row is an episode the task can play is
    :meth:`TestSet.check_playable`'s question."""
    path = Path(path)
    stored = path.resolve() == default_path(domain, task).resolve()
    # Only the stored test set is regenerated from its seed; someone else's file is theirs to fix.
    name = canonical(f"{domain}/{task}")
    advice = (
        f"regenerate it with: etmpc testset --task {name} --seed {stored_seed(name) or 'SEED'} --out {path}"
        if stored
        else "use the stored test set (drop --test-set) or a complete one"
    )
    if not path.is_file():
        raise TestSetError(f"test set {path} not found; {advice}")
    expected_file = checksum_path(path)
    if not expected_file.is_file():
        raise TestSetError(
            f"checksum file {expected_file} not found: a test set comes with the sha256 of its .npz beside it; {advice}"
        )
    expected = (expected_file.read_text(errors="replace").split() or [""])[0]
    actual = sha256_of(path)
    if actual != expected:
        raise TestSetError(
            f"test set {path} is corrupted: sha256 {actual[:12]}... != {expected[:12]}... in {expected_file.name}; {advice}"
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            # Read-only: every policy meets the same episodes, and nothing that plays one can change it.
            arrays = {name: readonly(data[name]) for name in data.files if name != "meta"}
            meta = loads(data["meta"].item())
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        raise TestSetError(f"test set {path} cannot be read ({exc}); {advice}") from None
    if not isinstance(meta, dict):
        raise TestSetError(f"test set {path} has no description (meta); {advice}")
    if (meta.get("domain"), meta.get("task")) != (domain, task):
        raise TestSetError(f"test set {path} is for {meta.get('domain')}/{meta.get('task')}, not {domain}/{task}")
    episodes = meta.get("episodes")
    if not isinstance(episodes, int) or isinstance(episodes, bool) or episodes < 1:
        raise TestSetError(f"test set {path} says it has {episodes!r} episodes; {advice}")
    if not arrays:
        raise TestSetError(f"test set {path} holds no episode arrays; {advice}")
    for name, values in arrays.items():
        if values.ndim < 1 or values.shape[0] != episodes:
            raise TestSetError(
                f"test set {path}: array {name!r} has shape {values.shape}, not one row per each of its "
                f"{episodes} episodes; {advice}"
            )
        if values.dtype.kind not in "fiu" or not np.all(np.isfinite(values)):
            raise TestSetError(f"test set {path}: array {name!r} is not all finite numbers; {advice}")
    return TestSet(path=path, sha256=actual, meta=meta, arrays=arrays)


def generate(system, seed: int, episodes: int, progress: bool = False) -> tuple[dict[str, np.ndarray], dict]:
    """Draw ``episodes`` episodes of ``system`` from ``seed``: the arrays and metadata of a test set
    (``progress``: the time left, on stderr)."""
    drawn = []
    with Progress(episodes, enabled=progress) as bar:
        for rng in episode_generators(seed, episodes):
            drawn.append(system.draw_episode(rng).arrays())
            bar.update()
    arrays = {name: np.stack([episode[name] for episode in drawn]) for name in drawn[0]}
    meta = {
        "format": FORMAT_VERSION,
        "domain": system.domain,
        "task": system.task,
        "seed": seed,
        "episodes": episodes,
        "generator": "numpy PCG64, one SeedSequence(seed).spawn(episodes) child per episode",
        "parameters": system.episode_parameters(),
    }
    return arrays, meta


def draw(system, seed: int, episodes: int, out: Path) -> str:
    """``etmpc testset``: ``episodes`` episodes of ``system`` drawn from ``seed`` into the new file
    ``out`` (an ``.npz``; ``--test-set`` takes it), with its sha256 beside it. Returns the sha256."""
    out = Path(out)
    if out.suffix != ".npz":
        raise EtmpcError(f"--out {out} does not end in .npz")
    if not 1 <= episodes <= 100_000:
        raise EtmpcError(f"--episodes must be in 1..100000, got {episodes}")
    for path in (out, checksum_path(out)):
        if path.exists():
            raise EtmpcError(f"{path} exists: a test set is never overwritten; choose another --out")
    check_outputs({"--out": out, "its checksum": checksum_path(out)})
    arrays, meta = generate(system, seed, episodes, progress=True)
    return write(out, arrays, meta)
