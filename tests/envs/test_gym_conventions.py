"""gymnasium's conventions on the trigger environments: each spec's ``max_episode_steps`` is the task's
episode length, read without making ``import etmpc`` heavy, and ``gymnasium.make``'s ``TimeLimit``
truncates at the very step the environment does."""

import subprocess
import sys

import gymnasium as gym
import pytest
from gymnasium.wrappers import TimeLimit

import etmpc  # noqa: F401  (registers the environments)
from etmpc.envs.registration import env_id
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.systems import make_system, names

from tests.conftest import REPO

TASKS = list(names())


def test_import_etmpc_stays_light_and_a_spec_reads_its_tasks_episode_length_when_asked():
    """In a fresh process: registering loads neither MuJoCo, dm-control nor CasADi; asking a spec for its time
    limit builds the task's System and answers the length the battery's parameters declare."""
    code = (
        "import sys, etmpc, gymnasium\n"
        "heavy = lambda: sorted(m for m in ('casadi', 'dm_control', 'mujoco') if m in sys.modules)\n"
        "print(heavy())\n"
        "spec = gymnasium.spec('etmpc/battery-trading-v1')\n"
        "print(heavy())\n"
        "from etmpc.systems.battery.parameters import Battery\n"
        "print(spec.max_episode_steps, Battery().episode_steps)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.splitlines() == ["[]", "[]", "100 100"]


def _ends(env: gym.Env, seed: int, steps: int) -> list[tuple[bool, bool]]:
    """``(terminated, truncated)`` of each of ``steps`` steps after ``reset(seed=seed)``, keeping every plan."""
    env.reset(seed=seed)
    return [tuple(env.step(0)[2:4]) for _ in range(steps)]


@pytest.mark.parametrize("task", TASKS)
def test_an_episode_has_exactly_the_tasks_steps_and_is_truncated_once(task):
    # The length the loop plays, counted on the dm_env environment underneath (no gymnasium wrapper there).
    core = TriggerEnvironment(task, seed=0)
    timestep, played = core.reset(), 0
    while not timestep.last():
        timestep, played = core.step(0), played + 1
    assert played == make_system(task).episode_steps
    assert gym.spec(env_id(task)).max_episode_steps == played
    env = gym.make(env_id(task))
    assert isinstance(env, TimeLimit) and env.spec.max_episode_steps == played
    last = [(False, False)] * (played - 1) + [(False, True)]
    for seed in (0, 1):  # and again after a reset: the wrapper's count starts over with the episode
        assert _ends(env, seed, played) == last
        with pytest.raises(RuntimeError, match="the episode is over: call reset"):
            env.step(0)  # no step beyond the end
    # Without the wrapper, the environment ends its episode at that same step by itself.
    assert _ends(gym.make(env_id(task), max_episode_steps=-1), 0, played) == last
