"""Starting Ray the same way in every job: attach to a cluster, or start a local one."""

from __future__ import annotations

import logging
import os


def init_ray(address: str = "", num_cpus: int = 2) -> None:
    """Attach to `address` (or $RAY_ADDRESS, set inside `ray job submit`), else start a local Ray.

    A plain ``ray.init()`` would silently attach to any cluster running on the
    machine; a local run asks for ``address="local"`` explicitly.
    """
    import ray

    if ray.is_initialized():
        return
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    env = {"env_vars": {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}}
    target = address or os.environ.get("RAY_ADDRESS", "")
    # Ray's own start-up lines (the token-authentication notice, "Started a local Ray instance") are INFO and
    # WARNING records of its Python logger: a job's log shows the job's lines, and Ray's errors still
    quiet = logging.ERROR
    if target:
        ray.init(address=target, runtime_env=env, log_to_driver=True, logging_level=quiet)
    else:
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, runtime_env=env,
                 log_to_driver=True, logging_level=quiet)
