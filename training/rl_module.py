"""RLlib new-API-stack RLModule around :class:`models.EOSPAgent`.

The observation reaches the module as the env's dict of padded tensors; it is
un-padded into one graph batch (no Python loop over nodes), the agent gives
per-node logits (forbidden actions already at a large negative value, so
masking holds on every forward path, the PPO loss's included) and a value from
the global node.  ``_forward_train`` returns the value through
``Columns.EMBEDDINGS`` so that ``compute_values`` needs no second GNN pass.

Rollout values (``model_config["rollout_values"]``, set from ``--train.rollout-values``):
the env runners' exploration pass also returns the value of each observation it
acts on (``Columns.VF_PREDS``, kept in the episodes), and GAE uses those instead of
a second pass of the whole batch in the learner, as PPO's reference implementation
does.  Only the artificial last step of each episode chunk, whose observation the
runner never acted on (the bootstrap value), goes through the learner's network.
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
        # the node features' width of the environment this module acts in (the single pass's, or the fleet's)
        space = getattr(self, "observation_space", None)
        x_space = space.spaces.get("x") if hasattr(space, "spaces") and isinstance(space.spaces, dict) else None
        self.agent = EOSPAgent(cfg, *([x_space.shape[-1]] if x_space is not None else []))
        self.rollout_values = bool(dict(self.model_config or {}).get("rollout_values", False))

    def _run(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        gb, node_valid = batch_from_padded(batch[Columns.OBS])
        logits, values = self.agent(gb)
        return self.agent.padded_logits(logits, node_valid), values

    def _forward(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        # acting only (env runners, evaluation): no autograd bookkeeping at all, ~10% faster than no_grad
        with torch.inference_mode():
            logits, _ = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits}

    def _forward_exploration(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        if not self.rollout_values:
            return self._forward(batch, **kwargs)
        with torch.inference_mode():
            logits, values = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits, Columns.VF_PREDS: self._value_output(values)}

    def _forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        logits, values = self._run(batch)
        return {Columns.ACTION_DIST_INPUTS: logits, Columns.EMBEDDINGS: values}

    def compute_values(self, batch: dict[str, Any], embeddings: Any | None = None) -> torch.Tensor:
        if embeddings is None:  # the advantage connectors' value pass (GAE targets): no gradient ever flows back
            if Columns.VF_PREDS in batch and Columns.LOSS_MASK in batch:
                return self._values_from_rollouts(batch)
            with torch.no_grad():  # so the attention runs its inference kernel, nothing is kept for a backward
                _, embeddings = self._run(batch)
        return self._value_output(embeddings)

    @staticmethod
    def _value_output(values: torch.Tensor) -> torch.Tensor:
        # one head: PPO's scalar value; several (lexicographic reward): all of them, [B, classes]
        return values[..., 0] if values.shape[-1] == 1 else values

    def _values_from_rollouts(self, batch: dict[str, Any]) -> torch.Tensor:
        """The runners' values of the real steps; the network's for the rows added after each episode chunk
        (``loss_mask`` false: their observation is the chunk's last, which the runner never acted on)."""
        values = torch.as_tensor(batch[Columns.VF_PREDS]).clone()
        extra = torch.nonzero(~torch.as_tensor(batch[Columns.LOSS_MASK]).bool()).reshape(-1)
        if extra.numel():
            obs = {k: v[extra] for k, v in batch[Columns.OBS].items()}
            with torch.no_grad():
                _, emb = self._run({Columns.OBS: obs})
            values[extra] = self._value_output(emb).to(values.dtype)
        return values
