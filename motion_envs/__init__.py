"""motion_envs: Gymnasium environments in which a learned human-motion prior is the simulator.

Importing the package registers every environment id with Gymnasium (see
`register_envs`).
"""

from __future__ import annotations

import gymnasium as gym

__version__ = "0.1.0"

ENV_SPECS: dict[str, tuple[str, str]] = {
    "motion_envs/GammaReach-v0": (
        "motion_envs.envs.gamma_reach:GammaReachEnv",
        "motion_envs.envs.gamma_reach:GammaReachVectorEnv",
    ),
    "motion_envs/GammaWander-v0": (
        "motion_envs.envs.gamma_wander:GammaWanderEnv",
        "motion_envs.envs.gamma_wander:GammaWanderVectorEnv",
    ),
    "motion_envs/WandrReach-v0": (
        "motion_envs.envs.wandr_reach:WandrReachEnv",
        "motion_envs.envs.wandr_reach:WandrReachVectorEnv",
    ),
    "motion_envs/ClopsNav-v0": (
        "motion_envs.envs.clops_nav:ClopsNavEnv",
        "motion_envs.envs.clops_nav:ClopsNavVectorEnv",
    ),
}
"""Environment id -> (entry point, native vector entry point)."""


def register_envs() -> list[str]:
    """Register every motion_envs id with Gymnasium; calling it again changes nothing.

    Returns:
        The ids registered by motion_envs.
    """
    for env_id, (entry_point, vector_entry_point) in ENV_SPECS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point)
    return sorted(ENV_SPECS)


register_envs()
