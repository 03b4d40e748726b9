"""The trained agent as an MLflow pyfunc model, logged "from code" (no pickled Python object).

MLflow loads this file and the artifact ``agent`` (a checkpoint directory:
``agent.pt`` read with ``weights_only=True`` + ``agent.json``); logged without that
artifact, it serves the shipped pretrained model of ``model_config={"mode": ...}``
(``mlflow.pyfunc.log_model(name=..., python_model=<this file>, model_config={"mode": "unitary"})``).  ``predict``
takes a DataFrame with a column ``instance_dir`` (interchange instance
directories) and returns, per instance, the number of acquisitions and the
utility of the schedule decoded greedily, and the schedule's node ids.
"""

from __future__ import annotations

import mlflow.pyfunc
import pandas as pd


class EOSPPolicyModel(mlflow.pyfunc.PythonModel):
    def load_context(self, context) -> None:
        import torch

        from eosp.solvers.policy import resolve_agent

        torch.set_num_threads(1)
        # a logged checkpoint, or (model logged without one) the shipped pretrained model of model_config["mode"]
        self.mode = mode = (context.model_config or {}).get("mode", "utility")
        self.agent, self.env_cfg, self.meta = resolve_agent("policy", context.artifacts.get("agent", ""), None, mode)

    def predict(self, context, model_input: pd.DataFrame, params=None) -> pd.DataFrame:
        from eosp.instances.interchange import read_instance
        from eosp.solvers.policy import PolicyConfig, solve

        rows = []
        for d in model_input["instance_dir"]:
            inst = read_instance(d)
            # the policy solver's defaults (guard, incumbent, polish), as `eosp solve --solver policy`
            nodes = solve(inst, PolicyConfig(mode=self.mode), agent=(self.agent, self.env_cfg, self.meta)).nodes
            value = float(inst.acqs.utility[inst.node_acq[nodes]].sum())
            rows.append({"instance_dir": d, "n_acquisitions": len(nodes), "value": value,
                         "nodes": inst.node_ids[nodes].tolist()})
        return pd.DataFrame(rows)


mlflow.models.set_model(EOSPPolicyModel())
