"""The trigger environments' gymnasium ids, registered on ``import etmpc`` without loading MuJoCo,
CasADi or the environment itself (gymnasium imports ``etmpc.envs.gym`` when one is made)."""

from __future__ import annotations

from etmpc.systems import DOMAINS, domain

VERSION = 0


def env_id(name: str) -> str:
    """``cart_pendulum`` or ``cart_pendulum/balance`` -> ``etmpc/cart_pendulum-balance-v0``."""
    domain_name, _, task = name.partition("/")
    return f"etmpc/{domain_name}-{task or domain(domain_name).TASKS[0]}-v{VERSION}"


def register() -> list[str]:
    """Register every task's environment with gymnasium (each once); returns their ids."""
    import gymnasium

    ids = []
    for domain_name in DOMAINS:
        for task in domain(domain_name).TASKS:
            ids.append(env_id(f"{domain_name}/{task}"))
            if ids[-1] not in gymnasium.registry:
                gymnasium.register(ids[-1], entry_point="etmpc.envs.gym:TriggerEnv", kwargs={"task": f"{domain_name}/{task}"})
    return ids
