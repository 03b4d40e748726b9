"""Lexicographic PPO: one value head and one advantage per priority class, highest class first.

The environment's ``lexicographic`` reward gives, at each step, a vector with 1 in
the component of the chosen acquisition's class (``info["reward_vector"]``; here it
is read back from the observation's class one-hot of the chosen node, so that no
info has to travel through RLlib's batches).  The learner then:

1. predicts one value per class (the agent's value head has 7 outputs);
2. computes GAE value targets and advantages A_c per class (gamma, lambda of the run);
3. standardizes each A_c over the batch (classes absent from the batch get 0);
4. combines them as  A = sum_c eps^c A_c  (eps = ``LEX_EPS`` = 0.01), then standardizes A.

With eps = 0.01, a change of one standard deviation in a class's advantage outweighs
a hundred standard deviations in the next one: the policy prefers any gain in a
higher class and uses the lower classes to break ties, without the 1e8 : 1 numeric
range of the raw utilities.  The PPO loss is the usual clipped surrogate on A, plus
the mean squared error of all heads, minus the entropy bonus.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from ray.rllib.connectors.common.numpy_to_tensor import NumpyToTensor
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.connectors.learner.general_advantage_estimation import GeneralAdvantageEstimation
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.numpy import convert_to_numpy
from ray.rllib.utils.postprocessing.value_predictions import compute_value_targets

from eosp.config import N_CLASSES
from eosp.envs.observation import NODE_FEATURES
from eosp.training.learner import EOSPPPOLearner

LEX_EPS = 0.01
CLASS_SLICE = slice(NODE_FEATURES.index("class_0"), NODE_FEATURES.index("class_0") + N_CLASSES)


def combine_advantages(adv: np.ndarray, present: np.ndarray, eps: float = LEX_EPS) -> np.ndarray:
    """adv [T, C] per-class advantages -> [T] lexicographic advantage (see the module docstring)."""
    out = np.zeros(adv.shape[0])
    for c in range(adv.shape[1]):
        if not present[c]:
            continue
        a = adv[:, c]
        out += eps ** c * (a - a.mean()) / max(1e-4, a.std())
    return (out - out.mean()) / max(1e-8, out.std())


class LexicographicGAE(ConnectorV2):
    """Learner connector computing per-class value targets and the combined advantage."""

    def __init__(self, input_observation_space=None, input_action_space=None, *, gamma, lambda_):
        super().__init__(input_observation_space, input_action_space)
        self.gamma, self.lambda_ = gamma, lambda_
        self._to_tensor = None

    def __call__(self, *, rl_module, episodes, batch: dict[str, Any], **kwargs):
        device = None
        out = {}
        for mid, mb in batch.items():
            module = rl_module[mid]
            values = module.compute_values(mb)
            device = values.device
            v = convert_to_numpy(values).reshape(values.shape[0], -1)  # [T, C]
            x = mb[Columns.OBS]["x"]
            actions = mb[Columns.ACTIONS].long()
            onehot = convert_to_numpy(x[torch.arange(x.shape[0], device=x.device), actions][:, CLASS_SLICE])
            rewards = convert_to_numpy(mb[Columns.REWARDS])
            r_vec = onehot * (rewards != 0)[:, None]  # the artificial last step of each episode has reward 0
            term = convert_to_numpy(mb[Columns.TERMINATEDS])
            trunc = convert_to_numpy(mb[Columns.TRUNCATEDS])
            targets = np.stack([compute_value_targets(values=v[:, c], rewards=r_vec[:, c], terminateds=term,
                                                      truncateds=trunc, gamma=self.gamma, lambda_=self.lambda_)
                                for c in range(v.shape[1])], axis=1)
            adv = combine_advantages(targets - v, r_vec.sum(0) > 0)
            out[mid] = {Postprocessing.ADVANTAGES: adv.astype(np.float32),
                        Postprocessing.VALUE_TARGETS: targets.astype(np.float32)}
        if self._to_tensor is None:
            self._to_tensor = NumpyToTensor(as_learner_connector=True, device=device)
        for mid, tensors in self._to_tensor(rl_module=rl_module, batch=out, episodes=episodes).items():
            batch[mid].update(tensors)
        return batch


class LexicographicPPOLearner(EOSPPPOLearner):
    """PPO whose GAE piece is :class:`LexicographicGAE` and whose value loss covers every head."""

    def build(self) -> None:
        super().build()
        self._learner_connector.remove(GeneralAdvantageEstimation)
        self._learner_connector.append(LexicographicGAE(gamma=self.config.gamma, lambda_=self.config.lambda_))

    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out):
        module = self.module[module_id].unwrapped()
        if Columns.LOSS_MASK in batch:
            mask = batch[Columns.LOSS_MASK]

            def mean(t):
                return torch.sum(t[mask]) / torch.sum(mask)
        else:
            mean = torch.mean
        dist = module.get_train_action_dist_cls().from_logits(fwd_out[Columns.ACTION_DIST_INPUTS])
        ratio = torch.exp(dist.logp(batch[Columns.ACTIONS]) - batch[Columns.ACTION_LOGP])
        adv = batch[Postprocessing.ADVANTAGES]
        surrogate = torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - config.clip_param, 1 + config.clip_param))
        values = module.compute_values(batch, embeddings=fwd_out.get(Columns.EMBEDDINGS))
        vf_loss = torch.mean((values - batch[Postprocessing.VALUE_TARGETS]) ** 2, dim=-1)
        entropy = dist.entropy()
        coeff = self.entropy_coeff_schedulers_per_module[module_id].get_current_value()
        total = mean(-surrogate + config.vf_loss_coeff * vf_loss - coeff * entropy)
        self.metrics.log_dict({"policy_loss": -mean(surrogate), "vf_loss": mean(vf_loss), "entropy": mean(entropy),
                               "total_loss": total}, key=module_id, window=1)
        return total
