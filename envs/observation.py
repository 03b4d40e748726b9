"""The agent's observation: the continuous graph of the current state, padded.

Nodes are acquisitions (index = action).  Edges are arcs of the continuous
graph, chosen by ``obs_edges``:

* ``"earliest"`` (default, what the GNN trains on): for every acquisition still
  in the graph, the arcs out of its earliest alive node, at most
  ``max_out_degree`` of them (the ones reaching the earliest starts), plus all the
  arcs out of the last scheduled node (one per allowed action).  These
  are the transitions that matter for the next decisions: the graph stays
  sparse (about n * k edges instead of the ~n^2 / 1.1 of the full continuous
  graph) and the learner's cost is driven by edges.
* ``"full"``: every surviving arc of the continuous graph (an arc i -> j stays
  while some discrete arc between alive nodes of i and j survives), truncated
  to ``max_edges``.

Node features (float32, :data:`NODE_FEATURES`), times relative to the end of
the last scheduled acquisition in units of :data:`TIME_SCALE` seconds.  Edge
features: the slack of the transition (start of the reached node minus the end
of the source node) and a flag for edges out of the last scheduled node.
"""

from __future__ import annotations

import numba
import numpy as np

from eosp.config import CLASS_UTILITIES, N_CLASSES

TIME_SCALE = 300.0
NODE_FEATURES = (
    "scheduled", "removed", "selectable", "last",
    "window_start", "window_end", "latest_start", "earliest_start", "alive_fraction",
    "duration", "log_utility", "utility_share",
    *(f"class_{c}" for c in range(N_CLASSES)),
    "roll_min", "roll_max", "roll_mean", "pitch_min", "pitch_max", "pitch_mean",
)
N_NODE_FEATURES = len(NODE_FEATURES)
N_EDGE_FEATURES = 2
N_STATIC = 3 + N_CLASSES + 6  # duration, log_utility, utility_share, classes, 6 attitude stats
assert N_NODE_FEATURES == 9 + N_STATIC


def static_features(duration: np.ndarray, utility: np.ndarray, priority: np.ndarray,
                    attitude: np.ndarray | None) -> np.ndarray:
    """The state-independent part of the node features, once per instance: [n, 3 + C + 6]."""
    n = duration.shape[0]
    out = np.zeros((n, 3 + N_CLASSES + 6), dtype=np.float32)
    out[:, 0] = duration / 60.0
    out[:, 1] = np.log10(utility) / np.log10(CLASS_UTILITIES[0])
    out[:, 2] = utility / utility.sum()
    out[np.arange(n), 3 + np.clip(priority, 0, N_CLASSES - 1)] = 1.0
    if attitude is not None:
        out[:, 3 + N_CLASSES:] = attitude / 90.0
    return out


@numba.njit(cache=True, inline="always")
def _clip(x):
    return min(10.0, max(-10.0, x))


@numba.njit(cache=True)
def build_observation(node_acq, node_time, node_finish, indptr, dst, acq_ptr, vtw_start, vtw_end, duration,
                      static, alive, alive_count, first_alive, scheduled, last, mask, k_out, k_last_cap, full,
                      x, edge_index, edge_attr):
    """Fill x [N_max, F], edge_index [2, E_max], edge_attr [E_max, 2]; returns the number of edges."""
    n = acq_ptr.shape[0] - 1
    e_max = edge_index.shape[1]
    t_now = node_finish[last]
    last_acq = node_acq[last]
    for i in range(n):
        total = acq_ptr[i + 1] - acq_ptr[i]
        x[i, 0] = scheduled[i]
        x[i, 1] = 1.0 if (alive_count[i] == 0 and scheduled[i] == 0) else 0.0
        x[i, 2] = mask[i]
        x[i, 3] = 1.0 if i == last_acq else 0.0
        x[i, 4] = _clip((vtw_start[i] - t_now) / TIME_SCALE)
        x[i, 5] = _clip((vtw_end[i] - t_now) / TIME_SCALE)
        x[i, 6] = _clip((vtw_end[i] - duration[i] - t_now) / TIME_SCALE)
        if alive_count[i] > 0:
            x[i, 7] = _clip((node_time[first_alive[i]] - t_now) / TIME_SCALE)
        else:
            x[i, 7] = 0.0
        x[i, 8] = alive_count[i] / total if total > 0 else 0.0
        for f in range(static.shape[1]):
            x[i, 9 + f] = static[i, f]
    # selectable: the earliest start is the node reached from the last one
    for a in range(indptr[last], indptr[last + 1]):
        v = dst[a]
        if alive[v]:
            x[node_acq[v], 7] = _clip((node_time[v] - t_now) / TIME_SCALE)

    m = 0
    # every allowed action gets its edge from the last node, whatever the instance size
    k_last = max(1, indptr[last + 1] - indptr[last])
    if k_last_cap > 0:
        k_last = min(k_last, k_last_cap)
    if last_acq >= 0:
        m = _edges_from(last, last_acq, 1.0, k_last, node_acq, node_time, node_finish, indptr, dst, alive,
                        edge_index, edge_attr, m, e_max)
    if full:
        stamp = np.full(n, -1, dtype=np.int64)
        for i in range(n):
            if alive_count[i] == 0:
                continue
            for u in range(first_alive[i], acq_ptr[i + 1]):
                if not alive[u]:
                    continue
                for a in range(indptr[u], indptr[u + 1]):
                    v = dst[a]
                    if alive[v] and stamp[node_acq[v]] != i and m < e_max:
                        stamp[node_acq[v]] = i
                        edge_index[0, m] = i
                        edge_index[1, m] = node_acq[v]
                        edge_attr[m, 0] = (node_time[v] - node_finish[u]) / 60.0
                        edge_attr[m, 1] = 0.0
                        m += 1
    else:
        for i in range(n):
            if alive_count[i] == 0:
                continue
            m = _edges_from(first_alive[i], i, 0.0, k_out, node_acq, node_time, node_finish, indptr, dst, alive,
                            edge_index, edge_attr, m, e_max)
    return m


@numba.njit(cache=True)
def _edges_from(u, i, flag, k, node_acq, node_time, node_finish, indptr, dst, alive, edge_index, edge_attr, m,
                e_max):
    """Append the (at most k) arcs out of node u to alive nodes reaching the earliest start times."""
    best_t = np.full(k, np.inf)
    best_v = np.full(k, -1, dtype=np.int64)
    for a in range(indptr[u], indptr[u + 1]):
        v = dst[a]
        if not alive[v]:
            continue
        t = node_time[v]
        if t >= best_t[k - 1]:
            continue
        s = k - 1
        while s > 0 and best_t[s - 1] > t:
            best_t[s] = best_t[s - 1]
            best_v[s] = best_v[s - 1]
            s -= 1
        best_t[s] = t
        best_v[s] = v
    for s in range(k):
        if best_v[s] < 0 or m >= e_max:
            break
        edge_index[0, m] = i
        edge_index[1, m] = node_acq[best_v[s]]
        edge_attr[m, 0] = (best_t[s] - node_finish[u]) / 60.0
        edge_attr[m, 1] = flag
        m += 1
    return m
