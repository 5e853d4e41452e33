"""The trigger environments' gymnasium ids, registered on ``import etmpc`` without loading MuJoCo,
CasADi or the environment itself (gymnasium imports ``etmpc.envs.gym`` when one is made). Every task of
the registry has one, a plugin's too."""

from __future__ import annotations

from etmpc.systems import domains, spec


def env_id(name: str) -> str:
    """``cart_pendulum`` or ``cart_pendulum/balance`` -> ``etmpc/cart_pendulum-balance-v0``: the task's
    version (:func:`~etmpc.systems.task_version`) is the id's. gymnasium answers an older version's id
    with a pointer to the current one."""
    return spec(name).gym_id


def register() -> list[str]:
    """Register every task's environment with gymnasium (each once); returns their ids."""
    import gymnasium

    ids = []
    for domain_name, package in domains().items():
        for task in package.TASKS:
            ids.append(env_id(f"{domain_name}/{task}"))
            if ids[-1] not in gymnasium.registry:
                gymnasium.register(ids[-1], entry_point="etmpc.envs.gym:TriggerEnv", kwargs={"task": f"{domain_name}/{task}"})
    return ids
