"""RLlib glue: the RLModule wrapping the agent, the PPO configuration, validation and MLflow logging.

Imports Ray; ``models`` and ``envs`` do not.
"""
