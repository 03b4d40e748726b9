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
the last scheduled acquisition in units of :data:`TIME_SCALE` seconds.  Six
look one step ahead (:func:`lookahead`, filled when ``look``, i.e. EnvConfig.lookahead;
zeros otherwise): for each allowed action, what the acquisitions it would remove from the
graph are worth.  The last six are Greedy's completion of the current partial schedule and
what Greedy would complete after each allowed action (:func:`plan_features`, filled when
EnvConfig.plan is set; zeros otherwise).  Edge features: the slack of the transition (start
of the reached node minus the end of the source node) and a flag for edges out of the last
scheduled node.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from eosp.config import CLASS_UTILITIES, N_CLASSES
from eosp.envs.core import EnvGraph, Episode, kill, step, sweep, sweep_horizon
from eosp.graphs.discrete import arc_to_acq
from eosp.planning.insertion import greedy_insert, insertion_order
from eosp.planning.labels import label_togo, togo_chain

TIME_SCALE = 300.0
NODE_FEATURES = (
    "scheduled", "removed", "selectable", "last",
    "window_start", "window_end", "latest_start", "earliest_start", "alive_fraction",
    "duration", "log_utility", "utility_share",
    *(f"class_{c}" for c in range(N_CLASSES)),
    "roll_min", "roll_max", "roll_mean", "pitch_min", "pitch_max", "pitch_mean",
    "loses_count", "loses_top", "loses_share", "excess_count", "excess_top", "excess_share",
    "plan_member", "plan_next", "plan_start", "after_loss", "after_best", "after_ratio",
)
N_NODE_FEATURES = len(NODE_FEATURES)
N_EDGE_FEATURES = 2
N_STATIC = 3 + N_CLASSES + 6  # duration, log_utility, utility_share, classes, 6 attitude stats
# column of each state-dependent feature (module constants: numba compiles them in)
SCHEDULED = NODE_FEATURES.index("scheduled")
REMOVED = NODE_FEATURES.index("removed")
SELECTABLE = NODE_FEATURES.index("selectable")
LAST = NODE_FEATURES.index("last")
WINDOW_START = NODE_FEATURES.index("window_start")
WINDOW_END = NODE_FEATURES.index("window_end")
LATEST_START = NODE_FEATURES.index("latest_start")
EARLIEST_START = NODE_FEATURES.index("earliest_start")
ALIVE_FRACTION = NODE_FEATURES.index("alive_fraction")
STATIC = NODE_FEATURES.index("duration")  # first of the N_STATIC columns of static_features, in their order
LOSES = NODE_FEATURES.index("loses_count")  # the six lookahead features (checkpoints without them: zeros)
N_LOOKAHEAD = 6
LOOKAHEAD_S = 300.0
PLAN = NODE_FEATURES.index("plan_member")  # the six plan features, last (checkpoints without them: zeros)
N_PLAN = 6
# EnvConfig.plan's kernel code: 0 off; 1 Greedy by utility, 2 by window start (unitary); 3 and 4: the better of
# that order and a second one (utility: by class, then window start; unitary: by latest start); 5 and 6: the
# label sweep (:func:`eosp.planning.labels.label_togo`) counting acquisitions (unitary) or summing utilities
PLAN_ORDERS = ("", "utility", "start", "utility+class", "start+deadline", "label:count", "label:utility")
UNITARY_PLANS = (2, 4, 5)  # the codes whose worth is a count
LABEL_PLANS = (5, 6)  # the codes that need no unpruned graph
assert STATIC == 9 and LOSES == STATIC + N_STATIC and PLAN == LOSES + N_LOOKAHEAD and N_NODE_FEATURES == PLAN + N_PLAN


class Candidates(NamedTuple):
    """The acquisitions' arrays the observation reads, prepared once per instance."""

    vtw_start: np.ndarray  # float64 [n]
    vtw_end: np.ndarray  # float64 [n]
    duration: np.ndarray  # float64 [n]
    static: np.ndarray  # float32 [n, N_STATIC]: static_features
    order_utility: np.ndarray  # int32 [n]: Greedy's insertion order in utility mode (decreasing utility)
    order_start: np.ndarray  # int32 [n]: and in unitary mode (by window start)
    order_class: np.ndarray  # int32 [n]: the second order in utility mode (by class, then window start)
    order_deadline: np.ndarray  # int32 [n]: and in unitary mode (by latest start)
    plan_indptr: np.ndarray  # CSR of the UNPRUNED graph (same nodes), for the plan features; [0] if not loaded
    plan_dst: np.ndarray
    utility: np.ndarray  # float64 [n]


def candidates(acqs, priority: np.ndarray, node_time: np.ndarray, acq_ptr: np.ndarray, unpruned=None) -> Candidates:
    """:class:`Candidates` of an instance's acquisitions (eosp.instances.instance.Acquisitions) in the
    environment's graph (its node start times and acquisition pointer); `unpruned`: the instance's unpruned
    discrete graph (eosp.graphs.discrete.DiscreteGraph, the same nodes) when loaded, which the plan features
    need (Greedy inserts acquisitions between others: the pruned graph has no arc across an insertable one)."""
    if unpruned is not None and unpruned.indptr.shape[0] == node_time.shape[0] + 1:
        indptr, dst = unpruned.indptr, unpruned.dst
    else:
        indptr, dst = np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int32)
    return Candidates(acqs.vtw_start, acqs.vtw_end, acqs.duration,
                      static_features(acqs.duration, acqs.utility, priority, acqs.attitude),
                      insertion_order(node_time, acq_ptr, acqs.utility, "utility"),
                      insertion_order(node_time, acq_ptr, acqs.utility, "start"),
                      np.lexsort((np.arange(len(priority)), node_time[acq_ptr[:-1]], priority)).astype(np.int32),
                      insertion_order(node_time, acq_ptr, acqs.utility, "deadline"), indptr, dst, acqs.utility)


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
def build_observation(g, ep, cand, opts, bufs):
    """Fill the buffers `bufs` = (x [N_max, F], edge_index [2, E_max], edge_attr [E_max, 2], plan_out); returns
    the number of edges.

    `g`: eosp.envs.core.EnvGraph, `ep`: eosp.envs.core.Episode (with first_alive advanced),
    `cand`: :class:`Candidates`; `opts` = (k_out, k_last_cap, full, horizon, look, plan), plain tuples (their
    NamedTuples would cost the dispatcher more than the step, see :func:`step_and_observe_fields`).
    `k_out`: edges out of each acquisition; `k_last_cap` (> 0): at most this many from the last one; `full`: every
    arc instead.  `horizon` > 0 (seconds): acquisitions that cannot be chosen now and whose earliest start is more
    than `horizon` after the end of the last scheduled one are left out of the graph (marked removed, no edge):
    the network's cost follows the near future only.  `look`: fill the lookahead features; `plan`
    (:data:`PLAN_ORDERS` code): fill the plan features, and `plan_out` (int32 [n + 1], or None) with the plan's
    nodes (see :func:`plan_features`).
    """
    k_out, k_last_cap, full, horizon, look, plan = opts
    x, edge_index, edge_attr, plan_out = bufs
    node_acq, node_time, node_finish, indptr, dst, acq_ptr = g.node_acq, g.node_time, g.node_finish, g.indptr, \
        g.dst, g.acq_ptr
    arcs = (node_acq, node_time, node_finish, indptr, dst)
    out = (edge_index, edge_attr)
    alive, alive_count, first_alive, scheduled, mask = ep.alive, ep.alive_count, ep.first_alive, ep.scheduled, \
        ep.mask
    static = cand.static
    last = ep.last[0]
    n = acq_ptr.shape[0] - 1
    e_max = edge_index.shape[1]
    t_now = node_finish[last]
    last_acq = node_acq[last]
    for i in range(n):
        total = acq_ptr[i + 1] - acq_ptr[i]
        x[i, SCHEDULED] = scheduled[i]
        x[i, REMOVED] = 1.0 if (alive_count[i] == 0 and scheduled[i] == 0) else 0.0
        x[i, SELECTABLE] = mask[i]
        x[i, LAST] = 1.0 if i == last_acq else 0.0
        x[i, WINDOW_START] = _clip((cand.vtw_start[i] - t_now) / TIME_SCALE)
        x[i, WINDOW_END] = _clip((cand.vtw_end[i] - t_now) / TIME_SCALE)
        x[i, LATEST_START] = _clip((cand.vtw_end[i] - cand.duration[i] - t_now) / TIME_SCALE)
        if alive_count[i] > 0:
            x[i, EARLIEST_START] = _clip((node_time[first_alive[i]] - t_now) / TIME_SCALE)
        else:
            x[i, EARLIEST_START] = 0.0
        x[i, ALIVE_FRACTION] = alive_count[i] / total if total > 0 else 0.0
        for f in range(static.shape[1]):
            x[i, STATIC + f] = static[i, f]
    # selectable: the earliest start is the node reached from the last one
    for a in range(indptr[last], indptr[last + 1]):
        v = dst[a]
        if alive[v]:
            x[node_acq[v], EARLIEST_START] = _clip((node_time[v] - t_now) / TIME_SCALE)
    if look:
        lookahead(g, ep, static, x)
    else:
        for i in range(n):
            for f in range(N_LOOKAHEAD):
                x[i, LOSES + f] = 0.0
    plan_features(g, ep, cand, plan, x, plan_out)
    beyond = np.zeros(n, dtype=np.bool_)
    if horizon > 0.0:
        for i in range(n):
            if alive_count[i] > 0 and mask[i] == 0 and node_time[first_alive[i]] > t_now + horizon:
                beyond[i] = True
                x[i, REMOVED] = 1.0

    m = 0
    # every allowed action gets its edge from the last node, whatever the instance size
    k_last = max(1, indptr[last + 1] - indptr[last])
    if k_last_cap > 0:
        k_last = min(k_last, k_last_cap)
    if last_acq >= 0:
        m = _edges_from(arcs, alive, beyond, last, last_acq, 1.0, k_last, out, m)
    if full:
        stamp = np.full(n, -1, dtype=np.int64)
        for i in range(n):
            if alive_count[i] == 0 or beyond[i]:
                continue
            for u in range(first_alive[i], acq_ptr[i + 1]):
                if not alive[u]:
                    continue
                for a in range(indptr[u], indptr[u + 1]):
                    v = dst[a]
                    if alive[v] and not beyond[node_acq[v]] and stamp[node_acq[v]] != i and m < e_max:
                        stamp[node_acq[v]] = i
                        edge_index[0, m] = i
                        edge_index[1, m] = node_acq[v]
                        edge_attr[m, 0] = (node_time[v] - node_finish[u]) / 60.0
                        edge_attr[m, 1] = 0.0
                        m += 1
    else:
        for i in range(n):
            if alive_count[i] == 0 or beyond[i]:
                continue
            m = _edges_from(arcs, alive, beyond, first_alive[i], i, 0.0, k_out, out, m)
    return m


@numba.njit(cache=True)
def lookahead(g, ep, static, x):
    """Fill the :data:`N_LOOKAHEAD` columns from :data:`LOSES` of x: for each allowed action a, the other
    acquisitions that taking a would remove from the graph (all their alive nodes before a's node, or
    unreachable from it): their number / 10, the highest log-utility feature among them, the sum of
    their utility shares; then the same three minus their least value over the allowed actions (what a
    loses beyond the most careful choice: a comparison across actions that message passing would
    otherwise have to learn).

    Why: the policy builds its schedule in time order and sees what an action kills only through a few
    hops of message passing; its costliest mistakes in utility mode are such actions (e.g. a class-1
    acquisition lost to a lower one).  This is the environment's step (the sweep of
    :func:`eosp.envs.core.sweep`) for every allowed action at once, without changing the state: one pass
    over the nodes in time order carries, per node, a bit set of the actions whose node reaches it
    (the OR of its predecessors'; an action's own other nodes die with it).  Only nodes starting within
    :data:`LOOKAHEAD_S` of the end of an action's node are swept for it: an acquisition with an alive
    node later than that counts as kept (slews longer than that are rare; the feature is a hint, not
    a bound).  Cost: one pass over the window's arcs, 64 actions to a machine word.
    """
    node_acq, node_time, node_finish, acq_ptr, order, pos = g.node_acq, g.node_time, g.node_finish, g.acq_ptr, \
        g.order, g.pos
    rindptr, rsrc, indptr, dst = g.rindptr, g.rsrc, g.indptr, g.dst
    alive, alive_count, first_alive, mask = ep.alive, ep.alive_count, ep.first_alive, ep.mask
    n = acq_ptr.shape[0] - 1
    last = ep.last[0]
    for i in range(n):
        for f in range(N_LOOKAHEAD):
            x[i, LOSES + f] = 0.0
    # the allowed actions, their nodes, and the window
    n_act = 0
    for a in range(n):
        n_act += mask[a]
    if n_act == 0:
        return
    act = np.empty(n_act, dtype=np.int64)
    target = np.empty(n_act, dtype=np.int64)
    bit_of = np.full(n, -1, dtype=np.int64)  # acquisition -> its action's bit
    k = 0
    p0 = order.shape[0]
    end = -np.inf
    for a in range(n):
        if mask[a] == 0:
            continue
        w = arc_to_acq(indptr, dst, acq_ptr, last, a)  # the node a would start at (eosp.envs.core.target_node)
        act[k] = a
        target[k] = w
        bit_of[a] = k
        p0 = min(p0, pos[w])
        end = max(end, node_finish[w] + LOOKAHEAD_S)
        k += 1
    words = (n_act + 63) // 64
    reach = np.zeros((order.shape[0] - p0, words), dtype=np.uint64)  # by time-order position - p0
    root_of = np.full(order.shape[0] - p0, -1, dtype=np.int64)
    for k in range(n_act):
        root_of[pos[target[k]] - p0] = k
    acc = np.zeros(words, dtype=np.uint64)
    full = np.zeros(words, dtype=np.uint64)
    for k in range(n_act):
        full[k >> 6] |= np.uint64(1) << np.uint64(k & 63)
    for p in range(p0, order.shape[0]):
        v = order[p]
        if node_time[v] > end:
            break
        if not alive[v]:
            continue
        acc[:] = 0
        for r in range(rindptr[v], rindptr[v + 1]):  # latest first: none before the window carries a bit
            q = rsrc[r]
            if pos[q] < p0:
                break
            if alive[q]:
                done = True
                for c in range(words):
                    acc[c] |= reach[pos[q] - p0, c]
                    done = done and acc[c] == full[c]
                if done:  # reached from every action's node: no predecessor can add more
                    break
        own = bit_of[node_acq[v]]
        if own >= 0:  # the action's other nodes die with it
            acc[own >> 6] &= ~(np.uint64(1) << np.uint64(own & 63))
        if root_of[p - p0] >= 0:
            kk = root_of[p - p0]
            acc[kk >> 6] |= np.uint64(1) << np.uint64(kk & 63)
        for c in range(words):
            reach[p - p0, c] = acc[c]
    # an acquisition is lost to action k when none of its alive nodes carries k's bit
    lost = np.zeros(n_act, dtype=np.int64)
    for i in range(n):
        if alive_count[i] == 0:
            continue
        v = acq_ptr[i + 1] - 1
        while v >= first_alive[i] and not alive[v]:
            v -= 1
        t_last = node_time[v]
        acc[:] = 0
        for u in range(first_alive[i], v + 1):
            if alive[u] and pos[u] >= p0:
                for c in range(words):
                    acc[c] |= reach[pos[u] - p0, c]
        for k in range(n_act):
            a = act[k]
            if a == i or t_last > node_finish[target[k]] + LOOKAHEAD_S:
                continue
            if (acc[k >> 6] >> np.uint64(k & 63)) & np.uint64(1) == 0:
                lost[k] += 1
                x[a, LOSES + 1] = max(x[a, LOSES + 1], static[i, 1])
                x[a, LOSES + 2] += static[i, 2]
    for k in range(n_act):
        x[act[k], LOSES] = lost[k] / 10.0
    # the same in excess of the allowed action that loses the least of each
    for f in range(3):
        least = np.inf
        for k in range(n_act):
            least = min(least, x[act[k], LOSES + f])
        for k in range(n_act):
            x[act[k], LOSES + 3 + f] = x[act[k], LOSES + f] - least


@numba.njit(cache=True)
def _completion(g, cand, plan, start, skip):
    """Greedy's completion from node `start` over the acquisitions not skipped, in the order(s) of kernel code
    `plan` (:data:`PLAN_ORDERS`): (acquisitions, nodes, worth), of the better order when there are two (ties to
    the first).  Worth: the sum of utilities, or the count for codes 2 and 4 (unitary)."""
    unitary = plan == 2 or plan == 4
    best_acqs, best_nodes, best = np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32), -1.0
    for k in range(2 if plan >= 3 else 1):
        if k == 0:
            order = cand.order_utility if plan == 1 or plan == 3 else cand.order_start
        else:
            order = cand.order_class if plan == 3 else cand.order_deadline
        acqs, nodes, _ = greedy_insert(cand.plan_indptr, cand.plan_dst, g.acq_ptr, g.node_time, order, start, skip)
        worth = float(acqs.shape[0])
        if not unitary:
            worth = 0.0
            for i in range(acqs.shape[0]):
                worth += cand.utility[acqs[i]]
        if worth > best * (1.0 + 1e-12) or best < 0.0:
            best_acqs, best_nodes, best = acqs, nodes, worth
    return best_acqs, best_nodes, best


@numba.njit(cache=True)
def _label_plan(g, ep, cand, plan):
    """The label sweep of kernel code `plan` (5: count, 6: utilities): (togo, nxt, the allowed action's node of
    largest togo or -1)."""
    n_nodes = g.node_time.shape[0]
    togo = np.empty(n_nodes)
    nxt = np.empty(n_nodes, dtype=np.int64)
    weight = np.ones(cand.utility.shape[0]) if plan == 5 else cand.utility
    label_togo(g, ep.alive, ep.last_pos[0], weight, togo, nxt)
    last, best, start = ep.last[0], -1.0, -1
    for a in range(ep.mask.shape[0]):
        if ep.mask[a]:
            w = arc_to_acq(g.indptr, g.dst, g.acq_ptr, last, a)
            if w >= 0 and togo[w] > best:
                best, start = togo[w], w
    return togo, nxt, start


@numba.njit(cache=True)
def plan_completion(g, ep, cand, plan):
    """The completion of the current partial schedule the plan :func:`plan_features` shows (kernel code
    `plan` > 0): (acquisitions, nodes, worth) after the last scheduled node: Greedy's, a path of the unpruned
    graph, or (codes 5, 6) the label sweep's best chain from an allowed action, a path of the environment's."""
    if plan == 5 or plan == 6:
        togo, nxt, start = _label_plan(g, ep, cand, plan)
        return togo_chain(g.node_acq, nxt, start, np.ones(cand.utility.shape[0]) if plan == 5 else cand.utility)
    n = cand.order_utility.shape[0]
    skip = np.zeros(n, dtype=np.uint8)
    for i in range(n):
        if ep.alive_count[i] == 0:
            skip[i] = 1
    return _completion(g, cand, plan, ep.last[0], skip)


@numba.njit(cache=True)
def plan_features(g, ep, cand, plan, x, plan_out=None):
    """Fill the :data:`N_PLAN` columns from :data:`PLAN` of x with Greedy's completion of the current partial
    schedule, and of the state after each allowed action: the operational greedy insertion
    (eosp.planning.insertion) run over the acquisitions still in the graph, in Greedy's order (`plan` 1:
    decreasing utility, 2: window start, every acquisition worth 1; 0: zeros, no work).  Codes 5 and 6
    (``--env.plan label``): the same columns from one backward label sweep
    (:func:`eosp.planning.labels.label_togo`, counting or summing utilities) instead: V(a) is the sweep's value
    of the node the step would start a at, and the plan the chain of the best action (a path of the environment's graph, starting with that action).  With
    `plan_out` (int32 [n + 1]): plan_out[0] = the plan's length (-1 with `plan` 0), then its nodes, so that a
    decoder keeping the best completed state reads the plan instead of computing it again.

    Columns, from the last scheduled node: the acquisition is in the plan; it is the plan's first; the start
    the plan gives it, relative to the end of the last scheduled acquisition (units of :data:`TIME_SCALE`; 0
    when not in the plan).  Then for each allowed action a, with V(a) = a's worth + the worth of Greedy's
    completion after a (from the node a would start at): what a loses against the best allowed action,
    max V - V(a), as log10(1 + loss) / 8 in utility (1: a top-class acquisition, 0.5: a class-2 one) or
    loss / 10 in unitary mode; 1 for the actions of largest V; V(a) / max V.  Zeros for the other actions.
    The completion after a is the plan the next state will show: Greedy over the acquisitions the
    environment's step to a keeps in the (pruned) graph, so V(a) is reachable in this MDP.

    The plan is a path of the UNPRUNED graph (`cand.plan_indptr`, `cand.plan_dst`): Greedy leaves gaps
    where something else would fit, which the pruned graph has no arc across, so its first acquisition need
    not be an allowed action (an allowed one then fits before it).

    Why: in utility mode the policy's costliest mistakes were high-class acquisitions given up, by steps
    whose effect shows many decisions later (two class-0 acquisitions that stop fitting together), while
    Greedy, which inserts by decreasing utility, never gives one up.  The plan says which acquisitions still
    fit together from here; V(a) is the rollout of Greedy after each action (taking the action of largest
    V at every step is the classic rollout policy, never worse than its base heuristic when that is
    sequentially consistent): the policy learns where to depart from both.  A function of the state
    (recomputed each step, so snapshots and search need nothing more); cost: one greedy insertion over the
    remaining acquisitions per allowed action and step.
    """
    n = cand.order_utility.shape[0]
    for i in range(n):
        for f in range(N_PLAN):
            x[i, PLAN + f] = 0.0
    if plan_out is not None:
        plan_out[0] = -1  # no plan (features off) until it is written below
    if plan == 0:
        return
    unitary = plan == 2 or plan == 4 or plan == 5
    alive_count, mask = ep.alive_count, ep.mask
    skip = np.empty(n, dtype=np.uint8)  # the acquisitions each action's rollout leaves out, filled per action
    last = ep.last[0]
    label = plan == 5 or plan == 6
    togo, nxt, start = np.empty(0), np.empty(0, dtype=np.int64), -1
    if label:  # one backward sweep values every action (label_togo)
        togo, nxt, start = _label_plan(g, ep, cand, plan)
        acqs, nodes, _ = togo_chain(g.node_acq, nxt, start, cand.utility)
    else:
        acqs, nodes, _ = plan_completion(g, ep, cand, plan)
    t_now = g.node_finish[last]
    for k in range(acqs.shape[0]):
        a = acqs[k]
        x[a, PLAN] = 1.0
        x[a, PLAN + 2] = _clip((g.node_time[nodes[k]] - t_now) / TIME_SCALE)
    if acqs.shape[0] > 0:
        x[acqs[0], PLAN + 1] = 1.0
    if plan_out is not None:  # the plan itself, for the policy solver's incumbent (EOSPEnv.completion)
        plan_out[0] = nodes.shape[0]
        for k in range(nodes.shape[0]):
            plan_out[1 + k] = nodes[k]
    # Greedy's rollout after each allowed action, from the state the environment's step would reach (codes 5, 6:
    # the label sweep's value of the node the step would start it at)
    value = np.full(n, -1.0)
    best = -1.0
    if label:
        for a in range(n):
            if mask[a]:
                value[a] = togo[arc_to_acq(g.indptr, g.dst, g.acq_ptr, last, a)]
                best = max(best, value[a])
    alive2 = np.empty_like(ep.alive)
    count2 = np.empty_like(alive_count)
    for a in range(n):
        if mask[a] == 0 or label:
            continue
        w = arc_to_acq(g.indptr, g.dst, g.acq_ptr, last, a)  # the node the step would start a at
        alive2[:] = ep.alive
        count2[:] = alive_count
        h = sweep_horizon(g, alive2, last, a)  # eosp.envs.core.apply_action on copies
        kill(g, alive2, count2, a)
        sweep(g, alive2, count2, g.pos[w], ep.last_pos[0], h)
        for i in range(n):
            skip[i] = 1 if count2[i] == 0 else 0
        _, _, after = _completion(g, cand, plan, w, skip)
        v = (1.0 if unitary else cand.utility[a]) + after
        value[a] = v
        best = max(best, v)
    for a in range(n):
        if value[a] < 0.0:
            continue
        loss = max(best - value[a], 0.0)
        x[a, PLAN + 3] = loss / 10.0 if unitary else np.log10(1.0 + loss) / 8.0
        x[a, PLAN + 4] = 1.0 if loss <= 1e-9 * best else 0.0
        x[a, PLAN + 5] = value[a] / best if best > 0.0 else 1.0


@numba.njit(cache=True)
def step_and_observe(g, ep, cand, action, opts, bufs):
    """eosp.envs.core.step, then :func:`build_observation` of the new state: one kernel call per environment
    step (each call unpacks the tuples again).  Returns (new node, number of edges); (-1, 0) and the state
    unchanged if `action` is not allowed."""
    w = step(g, ep, action)
    if w < 0:
        return w, 0
    return w, build_observation(g, ep, cand, opts, bufs)


@numba.njit(cache=True)
def step_and_observe_fields(g_fields, ep_fields, cand_fields, action, opts, bufs):
    """:func:`step_and_observe` called with ``tuple(g), tuple(ep), tuple(cand)``: the environment's hot path.

    Numba's dispatcher types a plain tuple of arrays about twice as fast as a NamedTuple, a noticeable share of
    a small instance's step; the NamedTuples are rebuilt here, for free.
    """
    return step_and_observe(EnvGraph(*g_fields), Episode(*ep_fields), Candidates(*cand_fields), action, opts, bufs)


@numba.njit(cache=True)
def _edges_from(arcs, alive, beyond, u, i, flag, k, out, m):
    """Append edges from acquisition i: the (at most k) arcs out of its node u to alive nodes reaching the
    earliest start times into `out` = (edge_index, edge_attr); returns the new number of edges.  `arcs` =
    (node_acq, node_time, node_finish, indptr, dst).

    Called once per acquisition: it takes the few arrays it reads, not the EnvGraph tuple, whose every
    array a call would reference-count (a large share of build_observation's time)."""
    node_acq, node_time, node_finish, indptr, dst = arcs
    edge_index, edge_attr = out
    e_max = edge_index.shape[1]
    best_t = np.full(k, np.inf)
    best_v = np.full(k, -1, dtype=np.int64)
    for a in range(indptr[u], indptr[u + 1]):
        v = dst[a]
        if not alive[v] or beyond[node_acq[v]]:
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
