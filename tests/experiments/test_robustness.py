"""``etmpc robustness`` checks all it is given before it plays anything: every value's system is built and every
policy parsed on each (a value that fails only when its system is made is refused in one line, the first value
never played), and its ``--out`` is a directory that takes the curve (:func:`~etmpc.experiments.robustness.check_out`)."""

import pytest

from etmpc.common.errors import EtmpcError
from etmpc.experiments import robustness as module
from etmpc.systems.registry import SystemKey

KICKS = "cart_pendulum/kicks"
OPTION = "disturbances.kick_scale"


@pytest.fixture
def nothing_played(monkeypatch):
    monkeypatch.setattr(module, "evaluate", lambda *a, **k: pytest.fail("a value was played before every one was checked"))


@pytest.mark.parametrize(
    "failure, says",
    [
        (EtmpcError("option solver.block: 50 is longer than the horizon"), "--vary disturbances.kick_scale=2.0: option solver"),
        (ZeroDivisionError("matrix is singular"), "the task cannot be built with it (matrix is singular)"),
    ],
)
def test_a_value_whose_system_cannot_be_made_is_refused_before_the_first_is_played(failure, says, monkeypatch, nothing_played):
    made = SystemKey.make

    def make(key):
        if dict(key.options).get(OPTION) == "2.0":
            raise failure
        return made(key)

    monkeypatch.setattr(SystemKey, "make", make)
    with pytest.raises(EtmpcError) as raised:
        module.robustness(KICKS, OPTION, ["0.5", "2"], ["every:3"], progress=False)
    assert says in str(raised.value) and "\n" not in str(raised.value)


def test_every_policy_is_parsed_on_every_values_system_before_any_is_played(monkeypatch, nothing_played):
    parsed = []

    def parse(system, policies):
        parsed.append(system.config)
        if len(parsed) == 2:
            raise EtmpcError("policy rl:p.json was made for another sensor")

    monkeypatch.setattr(module, "parse_policies", parse)
    with pytest.raises(EtmpcError, match=r"--vary disturbances.kick_scale=2.0: policy rl:p.json was made for another"):
        module.robustness(KICKS, OPTION, ["0.5", "2"], ["every:3"], progress=False)
    assert len(parsed) == 2 and parsed[0] != parsed[1]


def test_out_is_a_directory_that_is_new_empty_or_holds_an_earlier_curve(tmp_path):
    module.check_out(tmp_path / "new", ["every:3"])
    (tmp_path / "empty").mkdir()
    module.check_out(tmp_path / "empty", ["every:3"])
    (tmp_path / "earlier").mkdir()
    for name in module.FILES:
        (tmp_path / "earlier" / name).write_text("an earlier curve\n")
    module.check_out(tmp_path / "earlier", ["every:3"])
    (tmp_path / "earlier" / "notes.txt").write_text("mine\n")
    with pytest.raises(EtmpcError, match=r"holds files that are not a robustness curve's \(notes.txt\)"):
        module.check_out(tmp_path / "earlier", ["every:3"])
    (tmp_path / "afile").write_text("mine\n")
    with pytest.raises(EtmpcError, match="--out .*afile is not a directory"):
        module.check_out(tmp_path / "afile", ["every:3"])
