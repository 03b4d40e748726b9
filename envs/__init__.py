"""Gymnasium environments of the EOSP (importable without Ray).

``gymnasium.make("EOSP-v0", config=EnvConfig(...), source=...)``.
"""

import gymnasium as gym

from eosp.envs.eosp_env import EOSPEnv, InvalidAction  # noqa: F401

if "EOSP-v0" not in gym.registry:
    gym.register("EOSP-v0", entry_point="eosp.envs.eosp_env:EOSPEnv")
