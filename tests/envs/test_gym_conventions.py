"""gymnasium's conventions on the trigger environments: each spec's ``max_episode_steps`` is the task's
episode length, read without making ``import etmpc`` heavy, and ``gymnasium.make``'s ``TimeLimit``
truncates at the very step the environment does; ``render_mode`` draws the step (``rgb_array``) or shows
it (``human``, where there is a screen) and changes nothing else; ``gymnasium.make_vec`` and
``AsyncVectorEnv`` (forked or spawned subprocesses) play, seed and draw as one process does."""

import os
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import TimeLimit

import etmpc  # noqa: F401  (registers the environments)
from etmpc.common.errors import EtmpcError
from etmpc.envs.gym import TriggerEnv
from etmpc.envs.registration import env_id
from etmpc.envs.rendering import display
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.systems import make_system, names
from etmpc.views.video import render_frames

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


# -- render_mode ----------------------------------------------------------------------------------------
CART, BATTERY = env_id("cart_pendulum"), env_id("battery")
W, H = 160, 120


def _frame(env: gym.Env) -> np.ndarray:
    """``env.render()``, or a skip where this machine has no OpenGL for MuJoCo (etmpc says so in one line)."""
    try:
        return env.render()
    except EtmpcError as exc:
        if str(exc).startswith("cannot render with MUJOCO_GL"):
            pytest.skip(str(exc))
        raise


def test_a_scenes_frame_is_the_size_asked_and_shows_the_plants_state_as_etmpc_render_draws_it():
    env = gym.make(CART, render_mode="rgb_array", width=W, height=H)
    assert env.metadata["render_fps"] == 10.0  # one frame per control interval of 0.1 s
    env.reset(options={"test_episode": 34})
    loop = env.unwrapped.core.loop
    first, first_x = _frame(env), np.array(loop.x)
    assert first.shape == (H, W, 3) and first.dtype == np.uint8 and first.std() > 10  # not blank
    for _ in range(25):  # each plan kept as long as it lasts: the pole swings
        env.step(0)
    late = _frame(env)
    assert (late != first).any(axis=2).mean() > 0.05
    # The picture etmpc render draws of the loop's state, put into a physics of its own (system.show).
    system = env.unwrapped.core.system
    scene = system.make_env()
    scene.reset()
    drawn = render_frames(system, scene, np.array([first_x, loop.x]), W, H)
    for shown, expected in zip((first, late), drawn):
        assert (expected != shown).any(axis=2).mean() < 0.005
    env.close()
    env.close()  # closing twice does nothing


def test_a_task_without_a_scene_draws_a_chart_of_its_episode_so_far():
    env = gym.make(BATTERY, render_mode="rgb_array", width=W * 2, height=H * 2)
    assert env.metadata["render_fps"] == 0.1  # its control interval is 10 s
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (2 * H, 2 * W, 3) and first.dtype == np.uint8 and first.std() > 10
    for _ in range(20):
        env.step(1)
    later = env.render()
    assert (later != first).mean() > 0.01  # the curves grew
    env.reset(seed=0)
    np.testing.assert_array_equal(env.render(), first)  # the same episode at its start: the same picture


@pytest.mark.parametrize("task", ["cart_pendulum", "battery"])
def test_drawing_every_step_changes_nothing_the_environment_hands_out(task):
    def play(env):
        out = [env.reset(seed=7)[0]]
        for k in range(15):
            obs, reward, terminated, truncated, info = env.step(k % 4 == 0)
            out += [obs, reward, info["control_reward"]]
            if env.render_mode is not None:
                assert _frame(env).shape == (H, W, 3)
        return out

    drawn = play(gym.make(env_id(task), render_mode="rgb_array", width=W, height=H))
    plain = play(gym.make(env_id(task)))
    assert all(np.array_equal(a, b) for a, b in zip(drawn, plain, strict=True))


@pytest.mark.parametrize("task", ["cart_pendulum", "battery"])
def test_gymnasiums_checker_passes_with_its_render_checks(task):
    """check_env draws the environment made with rgb_array, then makes one of each mode the environment
    offers here and draws it: a frame of the wrong kind is a warning of gymnasium's, so none may come."""
    env = gym.make(env_id(task), render_mode="rgb_array", width=W, height=H)
    if task == "cart_pendulum":
        env.reset(seed=0)
        _frame(env)  # skips where there is no OpenGL
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught if "WARN" in str(w.message)] == []
    env.close()


def test_human_rendering_without_a_screen_is_one_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform in ("darwin", "win32"):
        pytest.skip("there is always a screen")
    env = gym.make(BATTERY)
    assert env.metadata["render_modes"] == ["rgb_array"]  # human is not offered here
    with pytest.raises(EtmpcError, match=r"^render_mode='human' needs a display, and DISPLAY is not set") as raised:
        gym.make(BATTERY, render_mode="human")
    assert "\n" not in str(raised.value)
    with pytest.raises(ValueError, match="render_mode must be None, 'rgb_array' or 'human', got 'ansi'"):
        TriggerEnv("battery", render_mode="ansi")
    with pytest.raises(ValueError, match="width: a frame's size in pixels is at least 1, got 0"):
        TriggerEnv("battery", render_mode="rgb_array", width=0)
    with pytest.raises(ValueError, match=r"width=2000, height=120 is larger than this scene's offscreen framebuffer \(1280x720"):
        TriggerEnv("cart_pendulum", render_mode="rgb_array", width=2000, height=120)
    with pytest.warns(UserWarning, match="render\\(\\) was called without a render_mode"):
        assert env.unwrapped.render() is None


def test_human_rendering_where_no_window_opens_is_one_clear_error(monkeypatch):
    pytest.importorskip("tkinter")
    if sys.platform in ("darwin", "win32") or os.path.exists("/tmp/.X11-unix/X97"):
        pytest.skip("display :97 may be real here")
    monkeypatch.setenv("DISPLAY", ":97")  # named, but no server behind it
    env = gym.make(BATTERY, render_mode="human")
    assert env.metadata["render_modes"] == ["rgb_array", "human"]
    with pytest.raises(EtmpcError, match=r"^render_mode='human' cannot open a window: couldn't connect to display \":97\""):
        env.reset(seed=0)
    env.close()


@pytest.mark.skipif(not display(), reason="no screen here")
def test_human_rendering_shows_each_step_in_a_window():
    """Where there is a screen (under Xvfb, e.g.): the window shows the step's frame, what rgb_array draws."""
    env = gym.make(BATTERY, render_mode="human", width=W * 2, height=H * 2)
    env.reset(seed=0)
    for _ in range(3):
        env.step(1)
    assert env.render() is None  # shown, as gymnasium has it
    window = env.unwrapped._window._label
    assert window.winfo_ismapped() and (window.winfo_width(), window.winfo_height()) >= (2 * W, 2 * H)
    if os.environ.get("DISPLAY"):  # what the screen shows where the window is
        from PIL import ImageGrab

        x, y = window.winfo_rootx(), window.winfo_rooty()
        pad = (window.winfo_width() - 2 * W) // 2, (window.winfo_height() - 2 * H) // 2
        shown = np.asarray(ImageGrab.grab((x + pad[0], y + pad[1], x + pad[0] + 2 * W, y + pad[1] + 2 * H), xdisplay=None))
        drawn = TriggerEnv("battery", render_mode="rgb_array", width=W * 2, height=H * 2)
        drawn.reset(seed=0)
        for _ in range(3):
            drawn.step(1)
        assert (shown[..., :3] != drawn.render()).any(axis=2).mean() < 0.005  # one step before differs at 4 % of them
    env.close()
    assert env.unwrapped._window._root is None  # closed


# -- vector environments --------------------------------------------------------------------------------
ACTIONS = [np.array([int(k % 3 == 0), 1]) for k in range(6)]  # copy 0 every:3, copy 1 always


def _vector_run(envs, seed: int, actions=ACTIONS) -> np.ndarray:
    """Each step's observations, ``(steps + 1, copies, size)``, after ``reset(seed=seed)``."""
    seen = [envs.reset(seed=seed)[0]]
    for action in actions:
        seen.append(envs.step(action)[0])
    return np.array(seen)


def _single_run(task: str, seed: int, copy: int, actions=ACTIONS) -> np.ndarray:
    """What copy ``copy`` plays, on an environment of its own seeded as gymnasium seeds that copy: ``seed + copy``."""
    env = gym.make(env_id(task))
    seen = [env.reset(seed=seed + copy)[0]]
    for action in actions:
        seen.append(env.step(int(action[copy]))[0])
    return np.array(seen)


def test_a_sync_vector_env_seeds_each_copy_apart_reproducibly_and_ends_their_episodes_together():
    envs = gym.make_vec(BATTERY, num_envs=2, vectorization_mode="sync")
    played = _vector_run(envs, 5)
    np.testing.assert_array_equal(_vector_run(envs, 5), played)  # the same seed, the same episodes
    assert not np.array_equal(played[:, 0], played[:, 1])  # two copies, two episodes
    for copy in (0, 1):
        np.testing.assert_array_equal(played[:, copy], _single_run("battery", 5, copy))
    # Both episodes end at the task's last step, truncated once; the next step starts new ones (at their zeros).
    steps = gym.spec(BATTERY).max_episode_steps
    envs.reset(seed=5)
    ends = [envs.step(np.array([0, 1]))[2:4] for _ in range(steps)]
    assert [bool(terminated.any() or truncated.any()) for terminated, truncated in ends[:-1]] == [False] * (steps - 1)
    assert not ends[-1][0].any() and ends[-1][1].all()
    obs, reward, terminated, truncated, _ = envs.step(np.array([0, 1]))
    assert not obs.any() and not reward.any() and not terminated.any() and not truncated.any()
    envs.close()


def test_an_async_vector_env_plays_in_subprocesses_what_one_process_plays():
    """The default start method (fork on Linux): MuJoCo and the compiled MPC in each subprocess."""
    envs = gym.make_vec(CART, num_envs=2, vectorization_mode="async")
    try:
        played = _vector_run(envs, 3)
    finally:
        envs.close()
    assert not np.array_equal(played[:, 0], played[:, 1])
    for copy in (0, 1):
        np.testing.assert_array_equal(played[:, copy], _single_run("cart_pendulum", 3, copy))


def test_a_spawned_subprocess_draws_its_scene():
    """Spawned, as etmpc's own workers are: the subprocess draws its copy's state with OpenGL, the picture this
    process draws of the same step (one copy: each spawned process starts Python, MuJoCo and the MPC afresh)."""
    spawned = {"vectorization_mode": "async", "vector_kwargs": {"context": "spawn"}}
    envs = gym.make_vec(CART, num_envs=1, render_mode="rgb_array", width=W, height=H, **spawned)
    try:
        played = _vector_run(envs, 3, [action[:1] for action in ACTIONS])
        try:
            (frame,) = envs.render()
        except EtmpcError as exc:
            if str(exc).startswith("cannot render with MUJOCO_GL"):
                pytest.skip(str(exc))
            raise
    finally:
        envs.close()
    assert envs.metadata["render_fps"] == 10.0
    here = gym.make(CART, render_mode="rgb_array", width=W, height=H)
    np.testing.assert_array_equal(played[:, 0], _single_run("cart_pendulum", 3, 0))
    here.reset(seed=3)
    for action in ACTIONS:
        here.step(int(action[0]))
    expected = _frame(here)
    assert frame.shape == (H, W, 3) and frame.dtype == np.uint8 and frame.std() > 10
    assert (frame != expected).any(axis=2).mean() < 0.005  # the step before differs at 19 % of the pixels


@pytest.mark.skipif(sys.platform != "linux", reason="fork is Linux's default start method")
@pytest.mark.filterwarnings("ignore:.*ERROR: ")  # gymnasium telling of the error it raises here
def test_a_process_forked_after_drawing_says_it_cannot_draw_rather_than_hang():
    drawn = gym.make(CART, render_mode="rgb_array", width=W, height=H)
    drawn.reset(seed=0)
    _frame(drawn)  # this process has drawn with OpenGL
    envs = gym.vector.AsyncVectorEnv([lambda: gym.make(CART, render_mode="rgb_array", width=W, height=H)], context="fork")
    try:
        envs.reset(seed=0)
        envs.call_async("render")
        with pytest.raises(EtmpcError, match="^this process was forked from one that had drawn with OpenGL") as raised:
            envs.call_wait(timeout=60)  # a hang would end here, as a TimeoutError
        assert "vector_kwargs={'context': 'spawn'}" in str(raised.value)
    finally:
        envs.close(terminate=True)


def test_gymnasium_make_takes_the_tasks_options_and_plays_them_as_evaluate_does():
    """``options`` through ``gymnasium.make``: the environment's system has them, and recomputing at every step
    of a stored test episode returns, summed, what ``etmpc evaluate --option ... --policy always`` reports there."""
    from etmpc.evaluation.evaluate import evaluate
    from etmpc.systems import system_key

    options = {"disturbances.kick_scale": "2"}
    env = gym.make(env_id("cart_pendulum/kicks"), options=options)
    assert env.unwrapped.core.system.config.disturbances.kick_scale == 2.0
    env.reset(options={"test_episode": 0})
    total, done = 0.0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(1)
        total, done = total + reward, terminated or truncated
    played = evaluate(system_key("cart_pendulum/kicks", None, options), ["always"], 1, workers=1, progress=False)
    plain = evaluate("cart_pendulum/kicks", ["always"], 1, workers=1, progress=False)
    objective = played.to_json()["runs"][0]["objective"]
    assert -total == pytest.approx(objective, rel=1e-12) and objective != plain.to_json()["runs"][0]["objective"]
    with pytest.raises(EtmpcError, match="unknown option 'disturbances.kick'"):
        gym.make(env_id("cart_pendulum/kicks"), options={"disturbances.kick": "2"})
