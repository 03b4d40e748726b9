"""GATv2 attention with typed edges, fused into one numba pass per layer on CPU.

Why not ``torch_geometric.nn.GATv2Conv``: on CPU, its message passing writes
about ten [edges, heads * hidden] tensors per layer (gathered sources and
targets, edge projections, their sum, the leaky ReLU, the attention product, the
messages) and autograd keeps them for the backward pass; with ~26k edges in a
128-observation minibatch that memory traffic is most of PPO's learning time.
Here one numba loop over each target node's incoming edges (CSR by target)
computes scores, softmax and the weighted sum with nothing per edge stored but
the attention weights [edges, heads]; the backward pass is a second loop with
the analytic gradients.  The function is the same as GATv2Conv's (same
parameters and names, so checkpoints load unchanged):

    z_e   = W_l x_j + b_l + W_r x_i + b_r + W_e f_e           (edge e = j -> i)
    s_e   = att . leaky_relu(z_e, 0.2)                          per head
    a_e   = softmax of s over the edges into i
    out_i = sum_e a_e (W_l x_j + b_l) + bias

The edge features of this model are an edge-type embedding plus a linear map
of two numeric attributes, so ``W_e f_e`` is a linear function of a 6-vector
(one-hot type, two attributes): the layer receives that [heads * hidden, 6]
matrix instead of a [edges, hidden] tensor (the same numbers, 5x fewer
multiplications and no [edges, hidden] input).

On other devices (a GPU learner) the same function runs as plain torch
scatter operations (:func:`attention_torch`), which is also the reference the
tests hold the kernel to.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import torch
from torch import nn

NEG_SLOPE = 0.2
N_TYPES = 4  # edge types of models.agent: precedence, reverse, to global, from global
N_BASIS = N_TYPES + 2  # one-hot type + the two numeric edge attributes


class EdgeStructure:
    """The edges of a graph batch sorted by target (CSR), shared by every layer of one forward pass."""

    def __init__(self, edge_index: torch.Tensor, types: torch.Tensor, attr: torch.Tensor, n_nodes: int):
        dst = edge_index[1]
        order = torch.argsort(dst, stable=True)
        self.src = edge_index[0][order].to(torch.int64).contiguous()
        self.dst = dst[order].to(torch.int64).contiguous()
        self.types = types[order].to(torch.int64).contiguous()
        self.attr = attr[order].to(torch.float32).contiguous()
        counts = torch.bincount(self.dst, minlength=n_nodes)
        self.indptr = torch.zeros(n_nodes + 1, dtype=torch.int64, device=dst.device)
        self.indptr[1:] = torch.cumsum(counts, 0)
        self.n_nodes = n_nodes
        self.max_degree = int(counts.max()) if counts.numel() else 0
        self._arrays: tuple | None = None

    @classmethod
    def from_csr(cls, indptr: np.ndarray, src: np.ndarray, dst: np.ndarray, types: np.ndarray, attr: np.ndarray,
                 max_degree: int) -> EdgeStructure:
        """Edges already sorted by target (CSR built elsewhere, e.g. by a numba pass): no sort here."""
        self = cls.__new__(cls)
        self.indptr, self.src, self.dst = torch.from_numpy(indptr), torch.from_numpy(src), torch.from_numpy(dst)
        self.types, self.attr = torch.from_numpy(types), torch.from_numpy(attr)
        self.n_nodes, self.max_degree = indptr.shape[0] - 1, max_degree
        self._arrays = (indptr, src, types, attr)
        return self

    def arrays(self) -> tuple:
        """(indptr, src, types, attr) as numpy arrays for the kernels (CPU), converted once per forward pass."""
        if self._arrays is None:
            self._arrays = (self.indptr.numpy(), self.src.numpy(), self.types.numpy(), self.attr.numpy())
        return self._arrays

    def basis(self) -> torch.Tensor:
        """The [edges, N_BASIS] features f_e: one-hot type, numeric attributes."""
        f = torch.zeros(self.src.shape[0], N_BASIS, dtype=self.attr.dtype, device=self.attr.device)
        f[torch.arange(self.src.shape[0], device=f.device), self.types] = 1.0
        f[:, N_TYPES:] = self.attr
        return f


# ----------------------------------------------------------------------------------------------
# numba kernels: arrays float32, xl / xr / out [N, H, C], w_edge [N_BASIS, H * C], att [H, C]


@numba.njit(cache=True, fastmath=True)
def _forward(edges, xl, xr, w_edge, att, out, alpha, score):
    """`edges`: (indptr, src, types, attr) (:meth:`EdgeStructure.arrays`); `w_edge` here [N_BASIS, H * C] (rows
    contiguous over the hidden units, for SIMD)."""
    indptr, src, types, attr = edges
    n, n_heads, c_dim = xl.shape
    for i in range(n):
        lo, hi = indptr[i], indptr[i + 1]
        if lo == hi:
            continue
        for h in range(n_heads):
            base = h * c_dim
            at, xri = att[h], xr[i, h]
            w4, w5 = w_edge[N_TYPES, base:base + c_dim], w_edge[N_TYPES + 1, base:base + c_dim]
            best = -np.inf
            for k in range(lo, hi):
                xlj, wt = xl[src[k], h], w_edge[types[k], base:base + c_dim]
                a0, a1 = attr[k, 0], attr[k, 1]
                s = np.float32(0.0)
                for c in range(c_dim):
                    z = xlj[c] + xri[c] + wt[c] + w4[c] * a0 + w5[c] * a1
                    s += at[c] * max(z, NEG_SLOPE * z)
                score[k - lo] = s
                best = max(best, s)
            total = np.float32(0.0)
            for k in range(lo, hi):
                e = math.exp(score[k - lo] - best)
                score[k - lo] = e
                total += e
            oi = out[i, h]
            for k in range(lo, hi):
                a = score[k - lo] / total
                alpha[k, h] = a
                xlj = xl[src[k], h]
                for c in range(c_dim):
                    oi[c] += a * xlj[c]


@numba.njit(cache=True, fastmath=True)
def _backward(edges, xl, xr, w_edge, att, alpha, gout, grads, dalpha, dz):
    """`edges`: (indptr, src, types, attr); `grads`: (gxl, gxr, gw, gatt), accumulated; `w_edge` and `gw`
    [N_BASIS, H * C]; `dz` a [C] scratch row.

    Per edge, dL/dz goes to `dz` first and is then added to each gradient in short loops that
    store into one or two arrays each: with all six accumulations in one loop LLVM cannot rule
    out that they alias and leaves it scalar (this way the pass is ~30% faster)."""
    indptr, src, types, attr = edges
    gxl, gxr, gw, gatt = grads
    n, n_heads, c_dim = xl.shape
    for i in range(n):
        lo, hi = indptr[i], indptr[i + 1]
        for h in range(n_heads):
            base = h * c_dim
            at, xri, gi, gxri, gatth = att[h], xr[i, h], gout[i, h], gxr[i, h], gatt[h]
            w4, w5 = w_edge[N_TYPES, base:base + c_dim], w_edge[N_TYPES + 1, base:base + c_dim]
            g4, g5 = gw[N_TYPES, base:base + c_dim], gw[N_TYPES + 1, base:base + c_dim]
            mean = np.float32(0.0)  # sum_e a_e dL/da_e
            for k in range(lo, hi):
                xlj = xl[src[k], h]
                d = np.float32(0.0)
                for c in range(c_dim):
                    d += gi[c] * xlj[c]
                dalpha[k - lo] = d
                mean += alpha[k, h] * d
            for k in range(lo, hi):
                j, t = src[k], types[k]
                xlj, gxlj = xl[j, h], gxl[j, h]
                wt, gt = w_edge[t, base:base + c_dim], gw[t, base:base + c_dim]
                a0, a1 = attr[k, 0], attr[k, 1]
                a = alpha[k, h]
                ds = a * (dalpha[k - lo] - mean)  # through the softmax
                for c in range(c_dim):
                    z = xlj[c] + xri[c] + wt[c] + w4[c] * a0 + w5[c] * a1
                    slope = np.float32(1.0) if z > 0 else np.float32(NEG_SLOPE)
                    gatth[c] += ds * slope * z
                    dz[c] = ds * at[c] * slope
                for c in range(c_dim):
                    gxlj[c] += dz[c] + a * gi[c]  # through z, and through the message
                for c in range(c_dim):
                    gxri[c] += dz[c]
                    gt[c] += dz[c]
                for c in range(c_dim):
                    g4[c] += dz[c] * a0
                    g5[c] += dz[c] * a1


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().contiguous().numpy()


def fused_forward(xl: np.ndarray, xr: np.ndarray, w_edge_t: np.ndarray, att: np.ndarray,
                  edges: EdgeStructure) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's forward pass: (out [N, H, C], attention weights [E, H])."""
    out = np.zeros_like(xl)
    alpha = np.empty((edges.src.shape[0], xl.shape[1]), dtype=np.float32)
    score = np.empty(max(edges.max_degree, 1), dtype=np.float32)
    _forward(edges.arrays(), xl, xr, w_edge_t, att, out, alpha, score)
    return out, alpha


class _FusedAttention(torch.autograd.Function):
    @staticmethod
    def forward(ctx, xl, xr, w_edge, att, edges: EdgeStructure):
        xl_n, xr_n, w_n, att_n = _np(xl), _np(xr), _np(w_edge.T), _np(att)
        out, alpha = fused_forward(xl_n, xr_n, w_n, att_n, edges)
        ctx.edges = edges
        ctx.arrays = (xl_n, xr_n, w_n, att_n, alpha)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, gout):
        edges = ctx.edges
        xl_n, xr_n, w_n, att_n, alpha = ctx.arrays
        gxl, gxr = np.zeros_like(xl_n), np.zeros_like(xr_n)
        gw, gatt = np.zeros_like(w_n), np.zeros_like(att_n)
        dalpha = np.empty(max(edges.max_degree, 1), dtype=np.float32)
        dz = np.empty(xl_n.shape[2], dtype=np.float32)
        _backward(edges.arrays(), xl_n, xr_n, w_n, att_n, alpha, _np(gout), (gxl, gxr, gw, gatt), dalpha, dz)
        return torch.from_numpy(gxl), torch.from_numpy(gxr), torch.from_numpy(gw.T.copy()), torch.from_numpy(gatt), None


def attention_torch(xl: torch.Tensor, xr: torch.Tensor, w_edge: torch.Tensor, att: torch.Tensor,
                    edges: EdgeStructure) -> torch.Tensor:
    """The same attention with torch scatter operations (any device; the kernel's reference)."""
    n, n_heads, c_dim = xl.shape
    ee = (edges.basis() @ w_edge.T).view(-1, n_heads, c_dim)
    z = xl[edges.src] + xr[edges.dst] + ee
    s = (nn.functional.leaky_relu(z, NEG_SLOPE) * att).sum(-1)  # [E, H]
    idx = edges.dst[:, None].expand_as(s)
    best = torch.full((n, n_heads), -torch.inf, dtype=s.dtype, device=s.device)
    best = best.scatter_reduce(0, idx, s, "amax", include_self=True)
    e = torch.exp(s - best[edges.dst])
    total = torch.zeros((n, n_heads), dtype=s.dtype, device=s.device).index_add_(0, edges.dst, e)
    a = e / total[edges.dst]
    return torch.zeros_like(xl).index_add_(0, edges.dst, xl[edges.src] * a[..., None])


def use_kernel(t: torch.Tensor) -> bool:
    return t.device.type == "cpu" and t.dtype == torch.float32


class GATv2Layer(nn.Module):
    """One GATv2 layer (concatenated heads, no self-loops) whose edge features are f_e (see module doc).

    Parameter names and shapes are those of ``torch_geometric.nn.GATv2Conv(d, d, heads, concat=True,
    edge_dim=d, add_self_loops=False)``: ``lin_l``, ``lin_r`` (with bias), ``lin_edge`` (no bias),
    ``att`` [1, heads, d], ``bias`` [heads * d].
    """

    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.heads, self.dim = heads, dim
        self.lin_l = nn.Linear(dim, heads * dim)
        self.lin_r = nn.Linear(dim, heads * dim)
        self.lin_edge = nn.Linear(dim, heads * dim, bias=False)
        self.att = nn.Parameter(torch.empty(1, heads, dim))
        self.bias = nn.Parameter(torch.zeros(heads * dim))
        # GATv2Conv's initialization: glorot over the last two dimensions, zero biases
        for w in (self.lin_l.weight, self.lin_r.weight, self.lin_edge.weight, self.att):
            bound = math.sqrt(6.0 / (w.shape[-2] + w.shape[-1]))
            nn.init.uniform_(w, -bound, bound)
        nn.init.zeros_(self.lin_l.bias)
        nn.init.zeros_(self.lin_r.bias)

    def forward(self, x: torch.Tensor, edges: EdgeStructure, edge_basis: torch.Tensor,
                fused: bool | None = None) -> torch.Tensor:
        """`edge_basis` [dim, N_BASIS]: the edge embedding of each basis feature (type rows, attribute maps)."""
        n = x.shape[0]
        xl = self.lin_l(x).view(n, self.heads, self.dim)
        xr = self.lin_r(x).view(n, self.heads, self.dim)
        w_edge = self.lin_edge.weight @ edge_basis  # [heads * dim, N_BASIS]
        att = self.att.view(self.heads, self.dim)
        if fused if fused is not None else use_kernel(x):
            if torch.is_grad_enabled():
                out = _FusedAttention.apply(xl, xr, w_edge, att, edges)
            else:  # inference: no autograd node, nothing kept for a backward pass
                out = torch.from_numpy(fused_forward(_np(xl), _np(xr), _np(w_edge.T), _np(att), edges)[0])
        else:
            out = attention_torch(xl, xr, w_edge, att, edges)
        return out.reshape(n, self.heads * self.dim) + self.bias
