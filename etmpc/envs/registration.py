"""The trigger environments' gymnasium ids, registered on ``import etmpc`` without loading MuJoCo,
CasADi or the environment itself (gymnasium imports ``etmpc.envs.gym`` when one is made). Every task of
the registry has one, a plugin's too. Each spec's ``max_episode_steps`` is the task's episode length,
read when first asked (:class:`~etmpc.envs.taskspec.TaskSpec`): ``gymnasium.make`` puts a ``TimeLimit``
of that length around the environment, which ends its episodes at that same step."""

from __future__ import annotations

from etmpc.systems import domains, spec


def env_id(name: str) -> str:
    """``cart_pendulum`` or ``cart_pendulum/balance`` -> ``etmpc/cart_pendulum-balance-v0``: the task's
    version (:func:`~etmpc.systems.task_version`) is the id's. gymnasium answers an older version's id
    with a pointer to the current one."""
    return spec(name).gym_id


def register() -> list[str]:
    """Register every task's environment with gymnasium (each once); returns their ids."""
    from dataclasses import fields

    import gymnasium

    from etmpc.envs.taskspec import TaskSpec

    ids = []
    for domain_name, package in domains().items():
        for task in package.TASKS:
            ids.append(env_id(f"{domain_name}/{task}"))
            if ids[-1] not in gymnasium.registry:
                gymnasium.register(ids[-1], entry_point="etmpc.envs.gym:TriggerEnv", kwargs={"task": f"{domain_name}/{task}"})
                spec = gymnasium.registry[ids[-1]]  # gymnasium's checks, then the same spec with the task's time limit
                gymnasium.registry[ids[-1]] = TaskSpec(**{f.name: getattr(spec, f.name) for f in fields(spec) if f.init})
    return ids
