"""RLlib new-API-stack RLModule around :class:`models.EOSPAgent`.

The observation reaches the module as the env's dict of padded tensors; it is
un-padded into one graph batch (no Python loop over nodes), the agent gives
per-node logits (forbidden actions already at a large negative value, so
masking holds on every forward path, the PPO loss's included) and a value from
the global node.  ``_forward_train`` returns the value through
``Columns.EMBEDDINGS`` so that ``compute_values`` needs no second GNN pass.
"""

from __future__ import annotations

import logging
from dataclasses import fields
from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule

from eosp.config import ModelConfig, from_dict
from eosp.models.agent import EOSPAgent, batch_from_padded


def drop_log_message(logger: str, text: str) -> None:
    """Drop the records of `logger` that contain `text` (once per process, for messages known harmless)."""
    log = logging.getLogger(logger)
    if not any(getattr(f, "eosp_text", None) == text for f in log.filters):
        f = logging.Filter()
        f.eosp_text = text
        f.filter = lambda record: text not in record.getMessage()
        log.addFilter(f)


# RLlib's RLModule.__init__ itself builds the deprecated RLModuleConfig (kept for old custom models), which
# warns in every process that builds a module, whatever the caller does (ray 2.5x): nothing to fix on our side.
drop_log_message("ray._common.deprecation", "RLModule(config=[RLModuleConfig object])")


class EOSPTorchRLModule(TorchRLModule, ValueFunctionAPI):
    """``model_config``: the fields of :class:`eosp.config.ModelConfig` as a dict."""

    def setup(self) -> None:
        # RLlib adds its own default keys to model_config: keep ours
        names = {f.name for f in fields(ModelConfig)}
        cfg = from_dict(ModelConfig, {k: v for k, v in dict(self.model_config or {}).items() if k in names})
        self.agent = EOSPAgent(cfg)

    def _run(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        gb, node_valid = batch_from_padded(batch[Columns.OBS])
        logits, values = self.agent(gb)
        return self.agent.padded_logits(logits, node_valid), values

    def _forward(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        # acting only (env runners, evaluation): no autograd bookkeeping at all, ~10% faster than no_grad
        with torch.inference_mode():
            logits, _ = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits}

    def _forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        logits, values = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits, Columns.EMBEDDINGS: values}

    def compute_values(self, batch: dict[str, Any], embeddings: Any | None = None) -> torch.Tensor:
        if embeddings is None:  # the advantage connectors' value pass (GAE targets): no gradient ever flows back
            with torch.no_grad():  # so the attention runs its inference kernel, nothing is kept for a backward
                _, embeddings = self._run(batch)
        # one head: PPO's scalar value; several (lexicographic reward): all of them, [B, classes]
        return embeddings[..., 0] if embeddings.shape[-1] == 1 else embeddings
