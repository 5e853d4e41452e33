"""The trigger environment as a ``gymnasium.Env`` (:class:`TriggerEnv`), registered for every task on
``import etmpc`` as ``etmpc/<domain>-<task>-v0`` (``gymnasium.make("etmpc/cart_pendulum-balance-v0")``).

Spaces: ``Discrete(2)`` actions (0 keep, 1 recompute; ``Discrete(3)`` on a task with compute levels:
0 keep, 1 one SQP iteration, 2 a full solve) and a float32 ``Box`` of
:attr:`TriggerEnv.observation_names` over the whole float32 range (the features are unbounded; a
diverged plant's are clipped to that range, never NaN). ``reset(seed=S)`` draws a training-distribution episode from
``gymnasium``'s generator seeded by ``S`` (the same ``S``, the same episode); ``reset(options=
{"test_episode": i})`` plays episode ``i`` of the stored test set. An episode ends ``truncated`` at the
task's time limit, ``terminated`` only when the plant fails. ``info`` holds the step's
``control_reward`` and ``computation_cost`` (the reward is their difference), whether it
``recompute``-d and whether that was ``forced``, and the episode's ``failures`` so far (an int, on
every task that counts them). See :mod:`etmpc.envs.trigger` for the rest.

``options={"sensor.noise_std": "0.01,0,0.01,0"}`` plays the task with some of its options set
(:mod:`etmpc.systems.options`; ``etmpc options --task TASK`` lists them), as ``--option`` does on the command line
and ``options=`` in :func:`etmpc.evaluate` and :func:`etmpc.score` (``test_set=`` too: the same keywords).
``task_options=``, its old name, works for this release with a ``DeprecationWarning``. (The constructor's
``options`` are the task's; ``reset(options={"test_episode": i})`` are gymnasium's, for one episode.)

``normalize="policies/<task>/ppo.json"`` hands out the observation normalised as that trained policy
saw it (:class:`~etmpc.envs.normalization.Normalization`: ``VecNormalize``'s statistics, frozen, read
from JSON): ``PPO.load`` of the shipped ``ppo.zip`` then decides on it as ``sb3:`` does. The spaces
stay the same (so ``PPO.load(path, env=env)`` takes it); ``info["observation"]`` is the raw one then.

gymnasium's conventions: ``gymnasium.make(ID)`` wraps it in a ``TimeLimit`` of the task's episode length
(the spec's ``max_episode_steps``), which truncates at the very step the environment does; an episode
has exactly that many steps. ``render_mode="rgb_array"`` draws each step (``width`` x ``height``, 640 x 480
by default) and ``"human"`` shows it in a window where there is a screen (:mod:`etmpc.envs.rendering`:
the 3-D scene, or the battery's chart); ``metadata["render_fps"]`` is one frame per control interval.
It works in ``gymnasium.make_vec`` and ``AsyncVectorEnv``: ``reset(seed=S)`` seeds copy ``i`` with ``S + i``.
"""

from __future__ import annotations

import os
import sys
from types import FrameType
from collections.abc import Mapping

import gymnasium
import numpy as np
from gymnasium import spaces

from etmpc.common.checks import BadValue, renamed
from etmpc.envs.normalization import Normalization
from etmpc.envs.rendering import HEIGHT, RENDER_MODES, WIDTH, Window, check_render, frames_for, render_modes
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.systems import SystemKey


def trigger_spaces(size: int, actions: int = 2) -> tuple[spaces.Box, spaces.Discrete]:
    """The observation and action spaces of a trigger environment with ``size`` features and ``actions``
    actions (3 on a task with compute levels), newly made (a saved model pickles them: made afresh, they
    pickle to the same bytes however they travelled)."""
    top = np.finfo(np.float32).max
    return spaces.Box(-top, top, shape=(size,), dtype=np.float32, seed=0), spaces.Discrete(actions, seed=0)


def _maker_level() -> int:
    """The ``stacklevel`` at which :func:`~etmpc.common.checks.renamed`, called by ``TriggerEnv.__init__``,
    names the line that made the environment: past gymnasium's own frames (``gymnasium.make``), so that the
    warning shows where Python shows a ``DeprecationWarning``, in the user's code."""
    level = 3  # renamed -> __init__ -> its caller
    frame: FrameType | None = sys._getframe(2)  # __init__'s caller
    while frame is not None and frame.f_globals.get("__name__", "").startswith("gymnasium"):
        level += 1
        frame = frame.f_back
    return level


class TriggerEnv(gymnasium.Env):
    """``gymnasium`` face of :class:`~etmpc.envs.trigger.TriggerEnvironment` (the same loop)."""

    # Every mode some environment offers, for gymnasium.make; each environment's own metadata says what it offers
    # here ("human" only where there is a screen) and its render_fps.
    metadata = {"render_modes": list(RENDER_MODES)}

    def __init__(
        self,
        task: str | SystemKey = "cart_pendulum",
        recompute_price: float | None = None,
        test_set: str | None = None,
        reward_baseline: str | None = None,
        normalize: str | os.PathLike | None = None,
        render_mode: str | None = None,
        width: int = WIDTH,
        height: int = HEIGHT,
        options=None,
        failure_cost: float = 0.0,
        *,
        task_options=None,
    ):
        options = renamed("options", options, "task_options", task_options, required=False, stacklevel=_maker_level())
        check_render(render_mode, width, height)  # before the MPC is built
        self.normalization = None if normalize is None else Normalization.read(normalize, task)  # before the MPC is built
        self.core = TriggerEnvironment(
            task,
            recompute_price=recompute_price,
            test_set=test_set,
            reward_baseline=reward_baseline,
            options=options,
            failure_cost=failure_cost,
        )
        self.observation_names = self.core.observation_names
        self.observation_space, self.action_space = trigger_spaces(len(self.observation_names), self.core.actions)
        system = self.core.system
        self.metadata = {"render_modes": render_modes(), "render_fps": 1.0 / system.control_interval_s}
        self.render_mode = render_mode
        physics = getattr(self.core.loop.env, "physics", None)  # the plant's, on a task with a 3-D scene
        self._frames = None if render_mode is None else frames_for(system, physics, int(width), int(height))
        self._window = Window(f"etmpc: {system.name}", self.metadata["render_fps"]) if render_mode == "human" else None

    @property
    def simulated_steps(self) -> int:
        """Control intervals simulated so far, the reward baseline's included."""
        return self.core.simulated_steps

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.core.generator = self.np_random
        if options is not None and not isinstance(options, Mapping):
            raise BadValue(f"reset options are a dict such as {{'test_episode': 3}}, got {type(options).__name__} {options!r}")
        options = dict(options or {})
        test_episode = options.pop("test_episode", None)
        if options:
            raise BadValue(f"unknown reset options {sorted(options)}; known: test_episode")
        timestep = self.core.reset(test_episode=test_episode)
        self._show()
        return self._observed(timestep.observation)

    def step(self, action):
        if self.core.loop.done:
            raise RuntimeError("the episode is over: call reset()")
        timestep = self.core.step(action)
        terminated = timestep.last() and timestep.discount == 0.0
        truncated = timestep.last() and not terminated
        obs, info = self._observed(timestep.observation)
        self._show()
        return obs, float(timestep.reward), terminated, truncated, info

    def _show(self) -> None:
        """Draw the step in the window, with ``render_mode="human"`` (which makes the window and its frames)."""
        if self._window is not None:
            assert self._frames is not None  # made with the window
            self._window.show(self._frames.frame(self.core))

    def render(self):
        """The current step drawn: an RGB frame, uint8 ``(height, width, 3)``, with ``render_mode="rgb_array"``;
        with ``"human"`` it is shown at every step already (and None is returned, as gymnasium has it)."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() was called without a render_mode: make the environment with render_mode='rgb_array' "
                f"(gymnasium.make({self.core.gym_id!r}, render_mode='rgb_array'))"
            )
            return None
        if self.core.episode is None:
            raise RuntimeError("nothing to draw before the first reset(): call reset()")
        assert self._frames is not None  # made with any render mode
        frame = self._frames.frame(self.core)
        if self._window is None:
            return frame
        self._window.show(frame)
        return None

    def close(self) -> None:
        """The frames' OpenGL context and the window, if any, are let go; closing again does nothing."""
        for part in (self._frames, self._window):
            if part is not None:
                part.close()

    def _observed(self, obs: np.ndarray) -> tuple[np.ndarray, dict]:
        """The observation handed out (normalised with ``normalize``) and the step's ``info``."""
        info = dict(self.core.info)
        if self.normalization is None:
            return obs, info
        return self.normalization(obs), info | {"observation": obs}
