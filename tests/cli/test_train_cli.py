"""`etmpc train --task TASK --algorithm NAME [--settings FILE] [--set KEY=VALUE ...]`: every registered learner,
its settings from a file and the command line; the old flags and `etmpc train-self` as the --set they
stand for, with a note; the seeds a learner cannot take refused; one-line errors."""

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import REPO
from etmpc.cli import main
from etmpc.cli.options import build_parser
from etmpc.cli.training import configure
from etmpc.common.errors import EtmpcError
from etmpc.learning import base
from etmpc.learning.base import Learner, learner_class

# Tiny runs of each built-in learner, in the new form (a settings file's lines and --set's alike).
TINY = {
    "gpomdp": (
        "battery",
        ["--seeds", "0,1"],
        "episodes: 2\neval_every: 1\neval_episodes: 2\nnormalisation_episodes: 2\n",
        ["validation_episodes=2", "learning_rate=3e-2", "baseline=mean"],
    ),
    "dpi": (
        "battery",
        ["--seeds", "1"],
        "episodes: 2\neval_every: 1\neval_episodes: 2\nnormalisation_episodes: 2\n"
        "bases: [always, every:3]\nselection_episodes: 2\n",
        ["validation_episodes=2", "futures=1", "horizon=3", "states_per_episode=2"],
    ),
    "self": (
        "cart_pendulum",
        [],
        "bases: [every:3, every:8]\nselection_episodes: 2\nridges: [0.1]\n",
        ["episodes=2", "solves_per_episode=2", "futures=1", "horizon=2", "validation_episodes=2"],
    ),
    "ppo": (
        "battery",
        ["--seeds", "3"],
        None,
        [
            "timesteps=512",
            "checkpoints=2",
            "validation_episodes=1",
            "n_steps=128",
            "batch_size=128",
            "n_epochs=1",
            "hidden=[16, 16]",
        ],
    ),
}
GPOMDP = ["--episodes", "2", "--eval-every", "1", "--eval-episodes", "2", "--validation-episodes", "2"]


def files(out: Path) -> dict:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def _sets(pairs: list[str]) -> list[str]:
    return [arg for pair in pairs for arg in ("--set", pair)]


@pytest.mark.parametrize("name", list(TINY))
def test_the_new_form_trains_every_built_in_learner_and_says_how_to_evaluate_it(name, tmp_path, capsys):
    if name == "ppo":
        pytest.importorskip("stable_baselines3")
    task, seeds, text, pairs = TINY[name]
    settings = []
    if text is not None:
        (tmp_path / "s.yml").write_text(text)
        settings = ["--settings", str(tmp_path / "s.yml")]
    out = tmp_path / "run"
    assert (
        main(
            ["train", "--task", task, "--algorithm", name, *settings, *_sets(pairs), *seeds, "--workers", "1", "--out", str(out)]
        )
        == 0
    )
    captured = capsys.readouterr()
    assert "warning" not in captured.err
    kind = learner_class(name).policy_kind
    last = captured.out.strip().splitlines()[-1]
    assert last.startswith(f"wrote {out}: ") and f"(evaluate it with: etmpc evaluate --task {task} --policy {kind}:{out}/" in last
    spec = last.split("--policy ", 1)[1].rstrip(")")
    assert Path(spec.split(":", 1)[1]).is_file()
    assert main(["evaluate", "--task", task, "--policy", spec, "--episodes", "1", "--workers", "1"]) == 0


def test_an_old_flag_gives_the_files_of_its_set_and_says_so_once(tmp_path, capsys):
    assert (
        main(
            [
                "train",
                "--task",
                "battery",
                "--algorithm",
                "gpomdp",
                "--seeds",
                "0",
                *GPOMDP,
                "--learning-rate",
                "0.1",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "old"),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    new = [
        "--set",
        "episodes=2",
        "--set",
        "eval_every=1",
        "--set",
        "eval_episodes=2",
        "--set",
        "validation_episodes=2",
        "--set",
        "learning_rate=0.1",
    ]
    assert (
        main(
            [
                "train",
                "--task",
                "battery",
                "--algorithm",
                "gpomdp",
                "--seeds",
                "0",
                *new,
                "--workers",
                "1",
                "--out",
                str(tmp_path / "new"),
            ]
        )
        == 0
    )
    assert files(tmp_path / "old") == files(tmp_path / "new")
    notes = [line for line in err.splitlines() if line.startswith("etmpc: warning:")]
    assert notes == [
        "etmpc: warning: --episodes is deprecated: use --set episodes=2",
        "etmpc: warning: --eval-every is deprecated: use --set eval_every=1",
        "etmpc: warning: --eval-episodes is deprecated: use --set eval_episodes=2",
        "etmpc: warning: --validation-episodes is deprecated: use --set validation_episodes=2",
        "etmpc: warning: --learning-rate is deprecated: use --set learning_rate=0.1",
    ]
    assert "warning" not in capsys.readouterr().err


def test_train_self_is_the_self_learner_with_a_note(tmp_path, capsys):
    args = ["--price", "5e-4", "--workers", "1"]
    assert (
        main(
            [
                "train-self",
                "--task",
                "cart_pendulum",
                "--out",
                str(tmp_path / "p.json"),
                "--episodes",
                "2",
                "--solves",
                "2",
                "--futures",
                "1",
                "--validation-episodes",
                "2",
                *args,
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    (note,) = [line for line in captured.err.splitlines() if "warning" in line]
    assert note == (
        "etmpc: warning: etmpc train-self is deprecated: use etmpc train --task cart_pendulum --algorithm self --out DIR "
        "--price 0.0005 --set episodes=2 --set solves_per_episode=2 --set futures=1 --set validation_episodes=2 "
        "(it writes DIR/selected.json)"
    )
    assert f"--policy self:{tmp_path / 'p.json'} --price 0.0005" in captured.out
    assert (
        main(
            [
                "train",
                "--task",
                "cart_pendulum",
                "--algorithm",
                "self",
                "--set",
                "episodes=2",
                "--set",
                "solves_per_episode=2",
                "--set",
                "futures=1",
                "--set",
                "validation_episodes=2",
                *args,
                "--out",
                str(tmp_path / "run"),
            ]
        )
        == 0
    )
    alias, new = (json.loads(p.read_text()) for p in (tmp_path / "p.json", tmp_path / "run" / "selected.json"))
    assert alias == new  # the same policy, wherever it is written


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--set", "episode=4"], "unknown setting 'episode' for dpi; known: episodes, eval_every, eval_episodes,"),
        (["--algorithm", "gpomdp", "--set", "futures=4"], "unknown setting 'futures' for gpomdp; known: "),
        (["--set", "episodes=0"], "episodes must be an integer >= 1, got 0"),
        (["--set", "episodes=many"], "episodes must be a whole number in -1e9..1e9, got 'many'"),
        # every setting of its annotated type before any work: a bool is no count, NaN no number, no count past 1e9
        (["--set", "episodes=true"], "episodes must be a whole number in -1e9..1e9, got True"),
        (["--set", "ridge=.nan"], "ridge must be a number (finite), got nan"),
        (["--set", "states_per_episode=100000000000000000000000"], "states_per_episode must be a whole number in -1e9..1e9"),
        (["--algorithm", "gpomdp", "--set", "discount=.inf"], "discount must be a number (finite), got inf"),
        (["--algorithm", "self", "--set", "bases=[always, 3]"], "bases must be a list of text, got ('always', 3)"),
        (["--algorithm", "ppo", "--set", "timesteps=100000000000000000000000"], "timesteps must be an integer in [1, 1e9]"),
        (["--algorithm", "ppo", "--set", "reward_baseline=bogus"], "reward_baseline: a fixed schedule (always, never, every:T"),
        (["--algorithm", "gpomdp", "--set", "learning_rate=-1"], "learning rate must be a finite number > 0, got -1"),
        (["--algorithm", "gpomdp", "--set", "baseline=median"], "baseline must be one of none, mean, state"),
        (["--algorithm", "ppo", "--set", "gamma=1.5"], "gamma must be in (0, 1], got 1.5"),
        (["--algorithm", "self", "--set", "ridges=[0]"], "ridges > 0"),
        (["--set", "episodes"], "argument --set: 'episodes' is not KEY=VALUE"),
        (["--set", "bases=[always"], "argument --set: bases: cannot read '[always'"),
        (["--algorithm", "reinforce"], "invalid choice: 'reinforce'"),
        (["--settings", "no/such.yml"], "no/such.yml: cannot read it"),
        # the seeds a learner cannot take
        (["--algorithm", "self", "--seeds", "0"], "--algorithm self takes no --seeds"),
        (["--algorithm", "ppo", "--seeds", "0-1"], "--algorithm ppo trains one seed at a time: give --seeds S, got 0-1"),
        (["--seeds", "2-1"], "bad --seeds '2-1'"),
        # an old flag: refused where it was not the learner's option, one line (no note)
        (
            ["--algorithm", "ppo", "--features", "paper"],
            "--features is a setting of gpomdp and dpi only, not of ppo: add --algorithm gpomdp",
        ),
        (["--algorithm", "ppo", "--learning-rate", "0.1"], "(or ppo's own learning_rate: --set learning_rate=…)"),
        (["--algorithm", "self", "--timesteps", "10"], "--timesteps is a setting of ppo only, not of self"),
        (["--algorithm", "dpi", "--horizon", "2", "--set", "horizon=0"], "horizon must be >= 1, got 0"),
        (["--hyperparams", "a.yml", "--settings", "b.yml"], "--hyperparams is --settings' old name"),
    ],
)
def test_bad_settings_and_seeds_are_one_line_and_exit_2(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--task", "battery", "--out", str(tmp_path / "run"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error: ") and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_set_reads_yaml_values_over_the_file_and_ppo_keeps_its_command_line_validation_episodes(tmp_path):
    dpi = learner_class("dpi")
    (tmp_path / "s.yml").write_text("episodes: 6\nfutures: 2\n")
    settings = configure(
        dpi, tmp_path / "s.yml", "battery", {"futures": 3, "bases": ["always", "every:4"], "eval_episodes": None}
    )
    assert (settings.episodes, settings.futures, settings.bases, settings.eval_episodes) == (6, 3, ("always", "every:4"), None)
    assert configure(learner_class("gpomdp"), None, "battery", {"learning_rate": "3e-4"}).learning_rate == 3e-4  # YAML 1.1's text
    ppo = learner_class("ppo")
    assert configure(ppo, None, "battery", {}).validation_episodes == 50  # as etmpc train and the shipped PPO chose
    assert configure(ppo, None, "battery", {"validation_episodes": 3}).validation_episodes == 3
    with pytest.raises(EtmpcError, match="unknown setting 'n_timesteps' for ppo; known: timesteps, seed"):
        configure(ppo, None, "battery", {"n_timesteps": 3})


@dataclass(frozen=True)
class PeriodSettings:
    period: int = 3
    validation_episodes: int = 1

    def __post_init__(self):
        if self.period < 1:
            raise EtmpcError(f"period must be >= 1, got {self.period}")


@pytest.fixture
def new_learner():
    """A learner defined here only: it answers every:PERIOD."""

    class FixedPeriod(Learner):
        name = "fixed-period-test"
        Settings = PeriodSettings
        seeding = "none"

        def setup(self):
            self.pick = None

        def milestones(self):
            return [1]

        def learn(self, budget, callback):
            callback(1)

        @property
        def chosen(self):
            return self.pick is not None

        def candidates(self):
            return {"it": f"every:{self.settings.period}"}

        def choose(self, scores):
            self.pick = f"every:{self.settings.period}"

        def policy(self):
            return self.pick

    yield FixedPeriod
    base.LEARNERS.pop(FixedPeriod.name)


def test_a_registered_learner_is_a_choice_of_algorithm_and_trains(new_learner, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "1000")  # argparse's lines, unbroken
    parser = build_parser()
    command = [a for a in parser._actions if a.dest == "command"][0].choices["train"]
    (train,) = [a for a in command._actions if a.dest == "algorithm"]
    assert "fixed-period-test" in train.choices
    assert list(train.choices)[:4] == ["gpomdp", "dpi", "self", "ppo"] and "fixed-period-test" in list(train.choices)
    help_text = " ".join(command.format_help().split())
    assert "gpomdp, dpi, self, ppo, fixed-period-test (default dpi" in help_text
    assert "fixed-period-test's: period, validation_episodes" in help_text
    assert (
        main(
            [
                "train",
                "--task",
                "battery",
                "--algorithm",
                "fixed-period-test",
                "--set",
                "period=4",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "run"),
            ]
        )
        == 0
    )
    assert "--policy every:4)" in capsys.readouterr().out
    assert (
        main(
            ["train", "--task", "battery", "--algorithm", "fixed-period-test", "--set", "period=0", "--out", str(tmp_path / "x")]
        )
        == 2
    )
    assert "period must be >= 1, got 0" in capsys.readouterr().err
    assert (
        main(["train", "--task", "battery", "--algorithm", "fixed-period-test", "--episodes", "3", "--out", str(tmp_path / "x")])
        == 2
    )
    assert "--episodes is a setting of gpomdp and dpi and self only, not of fixed-period-test" in capsys.readouterr().err


def test_the_pages_table_of_old_flags_is_the_command_lines():
    from etmpc.cli.legacy import FLAGS

    page = (REPO / "docs" / "learning.md").read_text()
    rows = [line for line in page.split("### The old flags (deprecated)", 1)[1].splitlines() if line.startswith("| `--")]
    table = {row.split("`")[1].split()[0]: row for row in rows}
    assert list(table) == [*FLAGS, "--hyperparams"]
    for flag, (name, owners, _) in FLAGS.items():
        assert f"`--set {name}=" in table[flag] and table[flag].rstrip(" |").endswith(", ".join(owners)), table[flag]
