"""The trigger environments' gymnasium ids, registered on ``import etmpc`` without loading MuJoCo,
CasADi or the environment itself (gymnasium imports ``etmpc.envs.gym`` when one is made). Every task of
the registry has one, a plugin's too. Each spec's ``max_episode_steps`` is the task's episode length,
read when first asked (:class:`~etmpc.envs.envspec.TaskEnvSpec`): ``gymnasium.make`` puts a ``TimeLimit``
of that length around the environment, which ends its episodes at that same step."""

from __future__ import annotations

from etmpc.systems import spec, specs


def env_id(name: str) -> str:
    """``cart_pendulum`` or ``cart_pendulum/balance`` -> ``etmpc/cart_pendulum-balance-v0``: the task's
    version (:func:`~etmpc.systems.task_version`) is the id's. gymnasium answers an older version's id
    with a pointer to the current one."""
    return spec(name).gym_id


def register() -> list[str]:
    """Register every task's environment with gymnasium (each once); returns their ids."""
    from dataclasses import fields

    import gymnasium

    from etmpc.envs.envspec import TaskEnvSpec

    ids = []
    for task in specs():  # the id is the task spec's, mechanically: etmpc/DOMAIN-TASK-vN
        ids.append(task.gym_id)
        if task.gym_id not in gymnasium.registry:
            gymnasium.register(task.gym_id, entry_point="etmpc.envs.gym:TriggerEnv", kwargs={"task": task.id})
            found = gymnasium.registry[task.gym_id]  # gymnasium's checks, then the same spec with the task's time limit
            gymnasium.registry[task.gym_id] = TaskEnvSpec(**{f.name: getattr(found, f.name) for f in fields(found) if f.init})
    return ids
