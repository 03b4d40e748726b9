"""The agent: node/edge embedders, graph rewiring, GATv2 layers, action and value heads.

Following the paper ("Solution" section):

* Rewiring: every precedence arc i -> j of the continuous graph gets a reverse
  arc j -> i with its own type, so information flows from future acquisitions
  to the present choice; one global node per graph is linked to every node in
  both directions (two more edge types); no self-loops: the residual keeps a
  node's own state, and every node hears at least the global node.
* Embeddings: an MLP over node features; edge types through an embedding table
  (plus a linear map of the edge's numeric attributes), both of size hidden_dim.
* ``n_layers`` GATv2 convolutions (models/gat.py) with edge attributes and ``heads`` heads, an MLP
  from heads * hidden_dim back to hidden_dim after each, residual connections.
* Action logits from the concatenation, for each node, of every layer's output
  (the embedding included) with the same for its graph's global node:
  ((n_layers + 1) * hidden_dim) * 2 per node, reduced to one logit by a linear
  layer.  Masked actions get -inf.  The value (one per priority class for the
  lexicographic reward) comes from the global node.

Nothing depends on the number of nodes: a model trained on 100 acquisitions runs
on 1500.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import torch
from torch import nn

from eosp.config import ModelConfig
from eosp.envs.observation import LAST, N_EDGE_FEATURES, N_NODE_FEATURES, REMOVED, SCHEDULED
from eosp.models.gat import N_TYPES, EdgeStructure, GATv2Layer

PRECEDENCE, REVERSE, TO_GLOBAL, FROM_GLOBAL = range(4)
MASKED = -1e9  # logit of a forbidden action


@dataclass
class GraphBatch:
    """Several graphs as one disjoint union (PyG convention)."""

    x: torch.Tensor  # float [total_nodes, F]
    edge_index: torch.Tensor  # long [2, total_edges], global node indices
    edge_attr: torch.Tensor  # float [total_edges, N_EDGE_FEATURES]
    batch: torch.Tensor  # long [total_nodes]: graph of each node
    n_nodes: torch.Tensor  # long [B]
    mask: torch.Tensor  # bool [total_nodes]: allowed actions

    @property
    def n_graphs(self) -> int:
        return int(self.n_nodes.shape[0])


def batch_from_padded(obs: dict[str, torch.Tensor]) -> tuple[GraphBatch, torch.Tensor]:
    """Un-pad a batch of environment observations (tensors with a leading batch dim).

    Only *active* acquisitions become nodes: still in the graph, or the last one
    scheduled.  Removed and earlier scheduled acquisitions can never be chosen and
    have no edge, so they would only cost compute (about half the nodes late in
    an episode).  Returns the graph batch and the bool [B, N_max] map of which
    padded slots are nodes.
    """
    x = obs["x"]
    b, n_max = x.shape[0], x.shape[1]
    n = obs["n_nodes"].reshape(b).long()
    m = obs["n_edges"].reshape(b).long()
    dev = x.device
    in_range = torch.arange(n_max, device=dev)[None, :] < n[:, None]
    active = (x[..., REMOVED] == 0) & ((x[..., SCHEDULED] == 0) | (x[..., LAST] == 1))  # not removed; not scheduled unless last
    node_valid = in_range & active
    slots = flat_index(node_valid)  # flattened slot of each node
    slot_to_node = torch.full((b * n_max,), -1, dtype=torch.long, device=dev)
    slot_to_node[slots] = torch.arange(slots.shape[0], device=dev)
    e_max = obs["edge_index"].shape[-1]
    edge_slots = flat_index(torch.arange(e_max, device=dev)[None, :] < m[:, None])  # [valid edges] in b * e_max
    graph_of_edge = edge_slots // e_max
    ei = obs["edge_index"].permute(1, 0, 2).reshape(2, b * e_max)[:, edge_slots].long()
    edge_index = slot_to_node[ei + (graph_of_edge * n_max)[None, :]]
    counts = node_valid.sum(1)
    gb = GraphBatch(
        x=x.reshape(b * n_max, -1)[slots].float(),
        edge_index=edge_index,
        edge_attr=obs["edge_attr"].reshape(b * e_max, -1)[edge_slots].float(),
        batch=torch.repeat_interleave(torch.arange(b, device=dev), counts),
        n_nodes=counts,
        mask=obs["action_mask"].reshape(-1)[slots] > 0,
    )
    return gb, node_valid


def flat_index(mask: torch.Tensor) -> torch.Tensor:
    """Positions of the true entries of `mask` flattened (long).  On CPU through numpy: torch's
    nonzero costs ~150 us per call on small masks, several times per forward pass."""
    if mask.device.type == "cpu":
        return torch.from_numpy(np.flatnonzero(mask.reshape(-1).numpy()))
    return torch.nonzero(mask.reshape(-1)).reshape(-1)


@numba.njit(cache=True)
def _rewired_csr(src, dst, attr, batch, total, b):
    """:meth:`EOSPAgent.rewire` followed by a stable sort by target, in one counting-sort pass.

    Edges into each target in the order of the concatenation [precedence, reverse, to global,
    from global], as ``torch.argsort(stable=True)`` would leave them.  Returns (indptr, src, dst,
    types, attr, max in-degree)."""
    n, e = total + b, src.shape[0]
    indptr = np.zeros(n + 1, np.int64)
    for k in range(e):
        indptr[dst[k] + 1] += 1
        indptr[src[k] + 1] += 1
    for i in range(total):
        indptr[i + 1] += 1
        indptr[total + batch[i] + 1] += 1
    max_degree = 0
    for i in range(n):
        max_degree = max(max_degree, indptr[i + 1])
        indptr[i + 1] += indptr[i]
    m = indptr[n]
    o_src, o_dst = np.empty(m, np.int64), np.empty(m, np.int64)
    o_type, o_attr = np.empty(m, np.int64), np.zeros((m, attr.shape[1]), np.float32)
    fill = indptr[:n].copy()
    for k in range(e):  # precedence arcs j -> i
        t = dst[k]
        q = fill[t]
        o_src[q], o_dst[q], o_type[q], o_attr[q] = src[k], t, PRECEDENCE, attr[k]
        fill[t] += 1
    for k in range(e):  # their reverses i -> j
        t = src[k]
        q = fill[t]
        o_src[q], o_dst[q], o_type[q], o_attr[q] = dst[k], t, REVERSE, attr[k]
        fill[t] += 1
    for i in range(total):  # node -> its global node
        t = total + batch[i]
        q = fill[t]
        o_src[q], o_dst[q], o_type[q] = i, t, TO_GLOBAL
        fill[t] += 1
    for i in range(total):  # global node -> node
        q = fill[i]
        o_src[q], o_dst[q], o_type[q] = total + batch[i], i, FROM_GLOBAL
        fill[i] += 1
    return indptr, o_src, o_dst, o_type, o_attr, max_degree


def _mlp(d_in: int, d_hidden: int, d_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d_in, d_hidden), nn.LeakyReLU(), nn.Linear(d_hidden, d_out))


class EOSPAgent(nn.Module):
    """`n_node_features`: columns of the observation's ``x`` (the single pass's by default; the constellation
    environment's observation has its own, eosp.envs.constellation_obs)."""

    def __init__(self, cfg: ModelConfig | None = None, n_node_features: int = N_NODE_FEATURES):
        super().__init__()
        cfg = cfg or ModelConfig()
        self.cfg = cfg
        h = cfg.hidden_dim
        self.node_embed = _mlp(n_node_features, h, h)
        self.global_init = nn.Parameter(torch.zeros(h))
        self.edge_type_embed = nn.Embedding(4, h)
        self.edge_attr_embed = nn.Linear(N_EDGE_FEATURES, h, bias=False)
        self.convs = nn.ModuleList(GATv2Layer(h, cfg.heads) for _ in range(cfg.n_layers))
        self.reduce = nn.ModuleList(_mlp(cfg.heads * h, h, h) for _ in range(cfg.n_layers))
        self.norms = nn.ModuleList(nn.LayerNorm(h) for _ in range(cfg.n_layers))
        width = (cfg.n_layers + 1) * h
        self.action_head = nn.Linear(2 * width, 1)
        self.value_head = _mlp(width, h, cfg.n_values)
        self.fused: bool | None = None  # None: the numba kernel on CPU float32, torch elsewhere (models/gat.py)
        assert self.edge_type_embed.num_embeddings == N_TYPES

    def rewire(self, gb: GraphBatch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Edge index over nodes + one global node per graph, edge types, numeric edge attributes."""
        total = gb.x.shape[0]
        dev = gb.x.device
        glob = total + gb.batch  # global node of each node's graph
        nodes = torch.arange(total, device=dev)
        src = torch.cat([gb.edge_index[0], gb.edge_index[1], nodes, glob])
        dst = torch.cat([gb.edge_index[1], gb.edge_index[0], glob, nodes])
        e = gb.edge_index.shape[1]
        types = torch.cat([torch.full((e,), PRECEDENCE, device=dev), torch.full((e,), REVERSE, device=dev),
                           torch.full((total,), TO_GLOBAL, device=dev), torch.full((total,), FROM_GLOBAL, device=dev)])
        attr = torch.cat([gb.edge_attr, gb.edge_attr, gb.x.new_zeros((2 * total, gb.edge_attr.shape[1]))])
        return torch.stack([src, dst]), types, attr

    def edges(self, gb: GraphBatch) -> EdgeStructure:
        """The rewired edges sorted by target.  On CPU one numba pass writes them straight into CSR (no
        concatenations, no argsort: ~5 ms of a 128-observation minibatch); elsewhere torch (:meth:`rewire`).
        Both give the same edges in the same order."""
        total, b = gb.x.shape[0], gb.n_graphs
        if gb.x.device.type != "cpu":
            return EdgeStructure(*self.rewire(gb), total + b)
        ei = gb.edge_index.numpy()
        return EdgeStructure.from_csr(*_rewired_csr(ei[0], ei[1], gb.edge_attr.numpy(), gb.batch.numpy(), total, b))

    def forward(self, gb: GraphBatch) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits [total_nodes] (forbidden actions at MASKED) and values [B, n_values]."""
        total, b = gb.x.shape[0], gb.n_graphs
        edges = self.edges(gb)
        # an edge's embedding is edge_type_embed(type) + edge_attr_embed(attr): linear in (one-hot type, attr)
        edge_basis = torch.cat([self.edge_type_embed.weight.T, self.edge_attr_embed.weight], dim=1)
        h = torch.cat([self.node_embed(gb.x), self.global_init.expand(b, -1)])
        layers = [h]
        for conv, red, norm in zip(self.convs, self.reduce, self.norms):
            h = norm(h + red(conv(h, edges, edge_basis, fused=self.fused)))
            layers.append(h)
        # action_head over [every layer of the node | the same of its global node], as a sum over layers of
        # two dot products: no [nodes, 2 * width] or [nodes, width] tensor whose slices would cost a zeroed
        # full-size gradient each in the backward pass
        w = self.action_head.weight[0].view(2, len(layers), -1)
        score_node = sum(h_l @ w[0, k] for k, h_l in enumerate(layers))  # [total + B]
        score_glob = sum(h_l[total:] @ w[1, k] for k, h_l in enumerate(layers))  # [B]
        logits = score_node[:total] + score_glob[gb.batch] + self.action_head.bias
        logits = torch.where(gb.mask, logits, torch.full_like(logits, MASKED))
        global_part = torch.cat([h_l[total:] for h_l in layers], dim=-1)  # [B, (n_layers + 1) * hidden]
        return logits, self.value_head(global_part) * (self.cfg.value_scale or 1.0)

    def padded_logits(self, logits: torch.Tensor, node_valid: torch.Tensor) -> torch.Tensor:
        """Scatter per-node logits back to the padded [B, N_max] layout (padding = MASKED)."""
        out = logits.new_full((node_valid.numel(),), MASKED)
        out[flat_index(node_valid)] = logits
        return out.reshape(node_valid.shape)
