"""A Gymnasium wrapper that logs every episode of an etmpc environment to Rerun: :class:`RerunLogger`.

Any learner's or script's episodes, as ``etmpc evaluate --record`` logs a policy's: the same
:class:`~etmpc.views.recording.Recorder` writes them from the same :class:`~etmpc.loop.records.EpisodeRecord`
(the states, the plans, each recompute and the objective), into a ``.rrd`` file that ``etmpc replay`` and
``rerun`` read, or live to a viewer (a ``rerun+http://`` URL, or ``spawn=True``).

>>> env = RerunLogger(gymnasium.make("etmpc/cart_pendulum-balance-v0"), "episodes.rrd", policy="ppo")
"""

from __future__ import annotations

from pathlib import Path

import gymnasium

from etmpc.common.errors import EtmpcError
from etmpc.loop.records import EpisodeRecord
from etmpc.views.recording import Recorder


class RerunLogger(gymnasium.Wrapper):
    """Log each episode of ``env`` (an etmpc environment, wrapped or not) when it ends, or is cut short by a
    ``reset`` or ``close``. ``recording``: a ``.rrd`` path, a viewer's URL (``rerun+http://HOST:PORT/proxy``),
    or a :class:`~etmpc.views.recording.Recorder` (``Recorder(spawn=True)`` for a viewer of its own);
    ``close`` finishes it (the file appears then). ``policy``: the name the episodes are shown under.

    Each episode's identity says its number in this wrapper (``episode``), the ``seed`` of its ``reset``
    (-1 if none) and the stored ``test_episode`` it played (-1 for a drawn one)."""

    def __init__(self, env: gymnasium.Env, recording: str | Path | Recorder, policy: str = "gymnasium"):
        super().__init__(env)
        core = getattr(env.unwrapped, "core", None)
        if core is None or not hasattr(core, "loop"):
            raise EtmpcError(f"RerunLogger logs an etmpc environment (etmpc/...-v*), got {env.unwrapped!r}")
        if not isinstance(policy, str) or not policy:
            raise EtmpcError(f"policy: a name to show the episodes under, got {policy!r}")
        self._core = core  # the environment's loop, played and logged (the same object for the env's life)
        self.recorder = recording if isinstance(recording, Recorder) else Recorder(recording)
        self.policy = policy
        self.logged = 0  # episodes logged so far
        self._pending = False  # an episode is being played and is not logged yet
        self._identity: dict = {}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._log()  # an episode cut short by this reset: logged as far as it went
        observation, info = super().reset(seed=seed, options=options)
        test_episode = (options or {}).get("test_episode")
        self._identity = {
            "policy": self.policy,
            "episode": self.logged,
            "repeat": 0,
            "seed": -1 if seed is None else int(seed),
            "test_episode": -1 if test_episode is None else int(test_episode),
        }
        self._pending = True
        return observation, info

    def step(self, action):
        observation, reward, terminated, truncated, info = super().step(action)
        if terminated or truncated:
            self._log()
        return observation, reward, terminated, truncated, info

    def close(self):
        try:
            self._log()
        finally:
            super().close()
            self.recorder.close()

    def _log(self) -> None:
        """The episode played since the last reset into the recording, once (nothing if no step was played)."""
        core = self._core
        if not self._pending or core.loop.trajectory.steps == 0:
            return
        self._pending = False
        self.recorder.log_episode(EpisodeRecord.from_trajectory(core.system, core.loop.trajectory, self._identity, core.episode))
        self.logged += 1
