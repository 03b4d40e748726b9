"""Typed configuration shared by the CLI, the Ray jobs and Tune.

Every knob of the project is a field of one of these dataclasses.  The CLI
(`eosp ...`) and the jobs (`jobs/*.py`) build their ``--help`` from them with
:mod:`eosp.args`, and every run records the dataclasses it used (``asdict``), so
a parameter such as ``hidden_dim`` goes from the command line
(``--model.hidden-dim``) to :class:`ModelConfig` to the layer that uses it.
"""

from __future__ import annotations

import numbers
from dataclasses import Field, dataclass, field, fields, is_dataclass
from typing import Any

def ranged(default: Any, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           zero_unsets: bool = False) -> Any:
    """A numeric field whose values (every element, for a tuple) must lie in [lo, hi] ((lo, hi] with
    `lo_open`); every float field must besides be finite.  Checked by :func:`check_value` wherever a
    value is set: command-line flags, :func:`apply_overrides`, :func:`from_dict`.  `zero_unsets`: an optional
    limit whose 0 on a command line means unset (None; :mod:`eosp.args`)."""
    meta = {"range": (lo, hi, lo_open), "zero_unsets": zero_unsets}
    if isinstance(default, tuple):
        return field(default_factory=lambda: default, metadata=meta)
    return field(default=default, metadata=meta)


WEEK_S = 604_800.0  # the longest time limit a solve accepts: a larger one is a typo, not a plan


def choice(default: str, *options: str) -> Any:
    """A string field restricted to `options`."""
    return field(default=default, metadata={"choices": options})


# The seven priority classes of the paper, highest first (priority 0 = highest,
# as in the interchange format).
CLASS_UTILITIES: tuple[float, ...] = (1e8, 1e6, 1e4, 6600.0, 3300.0, 120.0, 1.0)
N_CLASSES = len(CLASS_UTILITIES)


@dataclass
class OrbitConfig:
    """Where the satellite flies.  Circular sun-synchronous by default; a TLE overrides it."""

    altitude_km: float = 650.0
    """Altitude of the circular orbit; the inclination follows from sun-synchronism."""
    ltan_hours: float = 10.5
    """Local time of the ascending node (sets the orbit plane with respect to the Sun)."""
    day_of_year: int = 0
    """Day of the year (1..365) fixing the Sun direction; 0 draws one per instance."""
    tle: str = ""
    """Path of a two-line element file; when given the orbit is propagated with SGP4."""
    min_sun_elevation_deg: float = 10.0
    """Optical daylight constraint: Sun elevation at the target during its window."""


@dataclass
class SatelliteConfig:
    """Agility of the satellite: pointing limits and the slew-time model."""

    roll_max_deg: float = 45.0
    pitch_max_deg: float = 30.0
    slew_model: str = choice("piecewise", "piecewise", "bang_coast_bang")
    """'piecewise' (time as a piecewise-linear function of the rotation angle) or
    'bang_coast_bang' (maximum rate, acceleration and settling time)."""
    piecewise_angles_deg: tuple[float, ...] = (0.0, 5.0, 20.0, 45.0, 90.0, 180.0)
    piecewise_times_s: tuple[float, ...] = (12.0, 16.0, 25.0, 38.0, 60.0, 100.0)
    max_rate_deg_s: float = 1.5
    max_accel_deg_s2: float = 0.5
    settle_s: float = 8.0


@dataclass
class TargetConfig:
    """Where the candidate targets lie and what they are worth."""

    distribution: str = choice("uniform", "uniform", "clusters", "csv")
    """'uniform' (worldwide), 'clusters' (dense regional clusters) or 'csv' (user points)."""
    csv_path: str = ""
    """CSV with columns lat, lon (degrees) for distribution='csv'."""
    n_clusters: int = 4
    cluster_radius_km: float = 250.0
    duration_min_s: float = 10.0
    duration_max_s: float = 30.0
    class_probs: tuple[float, ...] = (0.03, 0.05, 0.08, 0.10, 0.14, 0.25, 0.35)
    """Mean share of each priority class, highest first; each instance draws its own mix."""
    class_mix_concentration: float = 20.0
    """Dirichlet concentration of the per-instance class mix (lower = more varied)."""
    drop_top_classes_prob: float = 0.3
    """Probability that an instance has no acquisition of the 1 or 2 highest classes."""
    high_priority_clustered: bool = False
    """Place the high classes (priority 0..2) close together so that they conflict."""
    cloud_weight: float = 1e-3
    """Utility = class value * (1 + cloud_weight * (1 - cloud cover)): never changes the class order."""


@dataclass
class GraphConfig:
    """How the discrete graph is built from the geometry."""

    step_s: float = 1.0
    """Discretization step of every window W_i = [e_i, l_i - d_i]."""


@dataclass
class InstanceConfig:
    """One generated instance: everything needed to reproduce it bit for bit."""

    n_acquisitions: int = ranged(100, 1)
    seed: int = 0
    family: str = choice("uniform", "uniform", "clusters", "conflict")  # the keys of FAMILIES
    """Generator family (uniform, clusters, conflict): its settings apply before other flags."""
    orbit: OrbitConfig = field(default_factory=OrbitConfig)
    satellite: SatelliteConfig = field(default_factory=SatelliteConfig)
    targets: TargetConfig = field(default_factory=TargetConfig)
    graph: GraphConfig = field(default_factory=GraphConfig)


# Named generator families; a data set says which one it comes from.
FAMILIES: dict[str, dict[str, Any]] = {
    # Worldwide uniform targets, classes drawn independently (top classes rare).
    "uniform": {"targets": {"distribution": "uniform"}},
    # Dense regional clusters: many conflicts, short slews.
    "clusters": {"targets": {"distribution": "clusters"}},
    # Clusters where the high classes sit close together and conflict with each other.
    "conflict": {"targets": {"distribution": "clusters", "high_priority_clustered": True,
                             "drop_top_classes_prob": 0.0}},
}


def family_config(family: str, n_acquisitions: int, seed: int, **overrides: Any) -> InstanceConfig:
    """The InstanceConfig of a named family, with `overrides` (dotted keys allowed) on top."""
    if family not in FAMILIES:
        raise ValueError(f"unknown instance family {family!r}; known: {', '.join(FAMILIES)}")
    cfg = InstanceConfig(n_acquisitions=n_acquisitions, seed=seed, family=family)
    apply_overrides(cfg, FAMILIES[family])
    apply_overrides(cfg, overrides)
    return cfg


def apply_overrides(cfg: Any, overrides: dict[str, Any]) -> Any:
    """Set fields of a (nested) dataclass from a dict; nested dicts or dotted keys reach sub-configs."""
    for key, value in overrides.items():
        head, _, rest = key.partition(".")
        if not any(f.name == head for f in fields(cfg)):
            raise ValueError(f"{type(cfg).__name__} has no field {head!r}")
        current = getattr(cfg, head)
        if rest:
            apply_overrides(current, {rest: value})
        elif is_dataclass(current) and isinstance(value, dict):
            apply_overrides(current, value)
        elif value is None and _optional(type(cfg), head):  # an optional field unset (a limit: no limit)
            setattr(cfg, head, None)
        else:
            setattr(cfg, head, check_value(type(cfg), head, _coerce(type(cfg).__name__, head, current, value)))
    return cfg


def _optional(cls: type, name: str) -> bool:
    """Whether field `name` of `cls` is annotated ``X | None``."""
    import typing

    return type(None) in typing.get_args(typing.get_type_hints(cls)[name])


def field_of(cls: type, name: str) -> Field:
    """The dataclass field `name` of `cls`."""
    return next(f for f in fields(cls) if f.name == name)


def check_value(cls: type, name: str, value: Any) -> Any:
    """`value` if field `name` of `cls` accepts it: floats finite, numbers in the field's range
    (:func:`ranged`), strings among its choices (:func:`choice`); else a one-line ValueError."""
    f = field_of(cls, name)
    items = value if isinstance(value, tuple) else (value,)
    for v in items:
        if isinstance(v, float) and v != v or isinstance(v, float) and v in (float("inf"), float("-inf")):
            raise ValueError(f"{cls.__name__}.{name}: must be a finite number, got {v!r}")
    if "range" in f.metadata:
        lo, hi, lo_open = f.metadata["range"]
        for v in items:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            if lo is not None and (v <= lo if lo_open else v < lo) or hi is not None and v > hi:
                where = (f"> {lo:g}" if lo_open else f">= {lo:g}") if hi is None else \
                    f"in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
                raise ValueError(f"{cls.__name__}.{name}: must be {where}, got {v!r}")
    if "choices" in f.metadata and value not in f.metadata["choices"]:
        raise ValueError(f"{cls.__name__}.{name}: must be one of {', '.join(f.metadata['choices'])}, got {value!r}")
    return value


def default_mlflow_uri(uri: str = "") -> str:
    """The given tracking URI, or the sqlite database mlflow.db in the working directory (absolute path:
    Tune trials and Ray workers run in other directories)."""
    from pathlib import Path

    return uri or f"sqlite:///{Path('mlflow.db').resolve()}"


def _coerce(owner: str, name: str, current: Any, value: Any) -> Any:
    """Check a new value against the field's current type (bool, int, float, str, tuple)."""
    def bad(expected: str) -> ValueError:
        return ValueError(f"{owner}.{name}: expected {expected}, got {value!r}")

    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise bad("true/false")
    elif isinstance(current, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("an integer")
    elif isinstance(current, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad("a number")
        value = float(value)
    elif isinstance(current, str):
        if not isinstance(value, str):
            raise bad("a string")
    elif isinstance(current, tuple):
        if not isinstance(value, (list, tuple)):
            raise bad("a list")
        value = tuple(value)
    return value


def validate_fields(cfg: Any) -> Any:
    """`cfg` when every field holds what it declares (:func:`check_value`: finite numbers in range, strings among
    the choices; a number where a range is declared, not a string or a bool), nested configs included; else a
    one-line ValueError naming the field.  For configs built in code (a library user's), which skip the parsing
    that checks command lines and dicts."""
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if is_dataclass(value):
            validate_fields(value)
            continue
        if "range" in f.metadata and value is not None:
            for v in value if isinstance(value, tuple) else (value,):
                if isinstance(v, bool) or not isinstance(v, numbers.Real):
                    raise ValueError(f"{type(cfg).__name__}.{f.name}: must be a number, got {v!r}")
            plain = tuple(v.item() if hasattr(v, "item") else v for v in (value if isinstance(value, tuple) else (value,)))
            value = plain if isinstance(value, tuple) else plain[0]  # numpy numbers checked as the Python ones
        check_value(type(cfg), f.name, value)
    return cfg


def to_dict(cfg: Any) -> dict[str, Any]:
    """A JSON-friendly dict of a dataclass (tuples become lists)."""
    out: dict[str, Any] = {}
    for f in fields(cfg):
        v = getattr(cfg, f.name)
        if is_dataclass(v):
            out[f.name] = to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = list(v)
        else:
            out[f.name] = v
    return out


def from_dict(cls: type, data: dict[str, Any]) -> Any:
    """Inverse of :func:`to_dict`; unknown keys are an error."""
    return apply_overrides(cls(), data)


def changed(cfg: Any, default: Any) -> dict[str, Any]:
    """Dotted keys of the fields where `cfg` differs from `default`."""
    a, b = flatten(cfg), flatten(default)
    return {k: v for k, v in a.items() if v != b[k]}


def flatten(cfg: Any, prefix: str = "") -> dict[str, Any]:
    """Dotted-key view of a nested config, for MLflow parameters."""
    out: dict[str, Any] = {}
    for f in fields(cfg):
        v = getattr(cfg, f.name)
        key = f"{prefix}{f.name}"
        if is_dataclass(v):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


@dataclass
class DatasetConfig:
    """A generated data set: `n_instances` instances in shards of `per_shard`."""

    out: str = "data/train"
    """Directory of the data set (shards and manifest.json)."""
    family: str = choice("uniform", "uniform", "clusters", "conflict")  # the keys of FAMILIES
    """Generator family (see eosp.config.FAMILIES)."""
    n_acquisitions: int = ranged(100, 1)
    n_instances: int = ranged(16, 1)
    per_shard: int = ranged(8, 1)
    seed: int = 0
    """Instance k of the data set uses seed + k: data sets with distant seeds do not overlap."""
    include_unpruned: bool = True
    """Also store the unpruned arcs (needed by greedy, exact, and schedule checks)."""
    instance: InstanceConfig = field(default_factory=InstanceConfig)
    """Generator settings applied on top of the family's (e.g. --instance.satellite.slew-model,
    --instance.orbit.tle, --instance.graph.step-s); n_acquisitions, seed and family come from above."""


@dataclass
class DemoConfig:
    """Expert demonstrations: the exact solver's schedules replayed as environment actions."""

    data: tuple[str, ...] = ("data/demo/train",)
    """Data sets (directories of shards with a manifest) to solve; demos go to <data>/demos/<mode>/."""
    modes: tuple[str, ...] = ("unitary", "utility")
    """Objectives solved: 'unitary' (count) and/or 'utility' (sum of utilities; serves the normalized and
    lexicographic rewards too)."""
    time_limit: float = ranged(30.0, 0, WEEK_S, lo_open=True)
    """Seconds of exact search per instance and mode; at the limit the best schedule found is kept with its gap."""
    action_sets: bool = True
    """Also label every step with the set of optimal actions (values of all allowed actions by RAMP's beam
    search on each child state): ties are common and a learner should not be taught one arbitrary choice."""
    beam: int = ranged(4, 1)
    """Beam of the search that values the allowed actions of a step (a lower bound of each value: a smaller
    beam can only miss optimal actions, never add a wrong one; 1 is about twice as fast as 4)."""
    sets_max_acquisitions: int = ranged(0, 0)
    """Label action sets only on instances of at most this many acquisitions (the cost grows about with the
    square of the size); larger ones keep the expert's action alone.  0: all."""
    prune: bool = True
    """Solve in the environment's pruned graph (what the policy plays in); must match the env's prune."""


@dataclass
class ImitationConfig:
    """Imitation pretraining on expert demonstrations (jobs/pretrain.py)."""

    train_data: tuple[str, ...] = ("data/demo/train",)
    """Data sets with demos (jobs/build_demos.py) for the objective of --env.reward."""
    val_data: str = "data/demo/val"
    """Validation data set (greedy decoding vs Greedy, RAMP and the exact optimum); empty: none."""
    preset: str = "cpu"
    """Model preset (MODEL_PRESETS); --model.* flags apply on top."""
    epochs: int = ranged(10, 1)
    """Passes over the demonstrations (and the states DAgger added)."""
    time_budget: float = ranged(0.0, 0)
    """Stop after this many seconds of training (0: no limit); the best checkpoint is kept."""
    batch_size: int = ranged(64, 1)
    lr: float = ranged(1e-3, 0, lo_open=True)
    lr_schedule: str = choice("constant", "constant", "cosine")
    """'cosine': the learning rate decays to 0 along a half cosine over the run (the time budget when one is set,
    else the epochs), so that the last epochs settle instead of jumping between DAgger rounds."""
    ema: float = ranged(0.0, 0.0, 0.9999)
    """Decay of an exponential moving average of the weights (e.g. 0.999, per batch; 0: off).  With it the
    average is what is validated and saved: a smoother policy than the last batch's weights."""
    weight_decay: float = 0.0
    value_coeff: float = 0.5
    """Weight of the value regression (remaining expert return) next to the action cross-entropy."""
    regret_coeff: float = 0.0
    """Weight of the expected regret under the policy, sum_a pi(a|s) (Q*(s) - Q(s,a)) / optimum, on states whose
    demos carry the values of all actions (jobs/build_demos.py --action-sets): it weighs each decision by what
    it costs, which the cross-entropy does not (utility mode: a top-class decision against a class-6 one)."""
    set_tolerance: float = 0.0
    """With action values: actions whose regret / optimum is at most this count as optimal (e.g. 1e-6 makes
    choices that differ by less than a millionth of the schedule's value ties)."""
    grad_clip: float = 1.0
    dagger_every: int = 0
    """Every this many epochs, roll out the current policy and label its states with the expert's optimal
    actions (DAgger); 0: plain behaviour cloning."""
    dagger_instances: int = 64
    """Training instances rolled out (sampling from the policy) per DAgger round."""
    dagger_beam: int = 4
    """Beam of the search that values the actions of DAgger states."""
    validate_every: int = 1
    """Validate every this many epochs (and after the last)."""
    max_val_instances: int = 0
    """Validate on the first N instances only (0: all)."""
    init_checkpoint: str = ""
    """Start from this agent checkpoint (e.g. a shipped model's folder, to train it further): its model
    configuration and value scale replace --model.*; empty: random initialization."""
    run_dir: str = "runs"
    run_name: str = ""
    overwrite: bool = False
    """Replace an existing run of this name (only one eosp wrote); without it, an existing run is refused."""
    mlflow_uri: str = ""
    experiment: str = "eosp-imitation"
    seed: int = 0


@dataclass
class RayConfig:
    address: str = ""
    """Ray cluster address; empty: the RAY_ADDRESS variable if set (submitted job), else a local Ray."""
    num_cpus: int = ranged(2, 1)
    """CPUs of the local Ray (ignored on a cluster)."""


@dataclass
class EnvConfig:
    """The EOSP environment (envs/eosp_env.py)."""

    reward: str = choice("normalized", "normalized", "utility", "unitary", "lexicographic")
    """'normalized' (utility / mean utility of the instance's candidates), 'unitary' (1 per
    acquisition), 'lexicographic' (per-class vector in info['reward_vector']) or 'utility' (raw)."""
    max_acquisitions: int = 128
    """Padding of the observation (nodes = actions); 0 sizes it to the instance (inference only)."""
    max_out_degree: int = 4
    """Edges kept per acquisition in the 'earliest' observation graph (4x that out of the last node)."""
    last_edges_cap: int = 0
    """Edges kept out of the last scheduled node; 0 = all of them (one per allowed action)."""
    prune: bool = True
    """Play in the pruned discrete graph (the paper); false: in the unpruned one."""
    obs_edges: str = "earliest"
    """'earliest' (sparse, for the GNN) or 'full' (the whole surviving continuous graph)."""
    obs_horizon_s: float = ranged(0.0, 0.0)
    """Observation horizon (s): acquisitions not selectable now whose earliest start is more than this after
    the current time are left out of the network's graph (cost follows the near future); 0 = the whole
    graph."""
    max_edges: int = 0
    """Edge padding; 0 = max_acquisitions * (max_out_degree + 4)."""
    lookahead: bool = False
    """Fill the six lookahead node features (what each allowed action would remove from the graph,
    envs/observation.py); false: they are zeros and the step skips that work (~0.08 ms a step at 100
    acquisitions, ~2 ms at 1000).  Recorded in checkpoints with the other env settings."""
    plan: str = choice("", "", "greedy", "greedy2", "label")
    """'greedy': fill the six plan node features: Greedy's completion of the current partial schedule (the
    operational greedy insertion from the last scheduled node, in Greedy's order for the reward: decreasing
    utility, window start for 'unitary') and, for each allowed action, the worth of Greedy's completion after
    it (envs/observation.py).  'greedy2': the better of two insertion orders each time (utility: also by class
    then window start; unitary: also by latest start), at up to twice the insertion work.  Needs the
    instances' unpruned arcs.  'label': the same six features from one backward label sweep per step over the
    environment's graph (one label per node; planning/labels.label_togo) instead of Greedy: each allowed action's
    value is the best chain found from the node it would start at, the plan the best of them; counts in
    'unitary', utilities otherwise; no unpruned arcs needed.  Empty: zeros, no work.  Recorded in checkpoints
    with the other env settings."""
    shards: tuple[str, ...] = ()
    """Shard files (or data set directories) the environment copies share out among themselves."""
    seed: int = 0
    """Seed of the instance draws (combined with the worker and vector index)."""
    max_cached_instances: int = 256


@dataclass
class FleetEnvConfig:
    """The multi-agent constellation environment (envs/constellation.py): one agent per satellite."""

    reward: str = choice("wcr", "wcr", "cr")
    """'wcr': a newly served task earns its weight / the fleet's total weight (an episode's return is the schedule's
    WCR); 'cr': 1 / the number of tasks (the return is its CR, the unitary variant)."""
    team_reward: float = ranged(0.0, 0.0, 1.0)
    """Share of every reward that goes to the whole fleet: each agent receives (1 - share) x its own rewards plus
    share x everything the fleet served, at its next observation (0: each agent earns only what it serves)."""
    max_satellites: int = ranged(0, 0)
    """Agent slots sat_0 .. sat_{K-1}; 0 = the largest fleet of the source.  A fleet with more satellites is refused."""
    max_nodes: int = ranged(128, 2)
    """Nodes of the padded observation graph: node 0 is 'skip to the next pass', the others the tasks of the pass."""
    truncate: bool = False
    """When a pass has more tasks than max_nodes - 1, show the first ones (the last observed task, the selectable
    ones by start, then the others by earliest start); false: such a pass is refused when the fleet is loaded."""
    max_out_degree: int = ranged(4, 1)
    """Edges kept out of each task's earliest node ahead (to the earliest starts); every selectable task also gets
    the edge from the last observation."""
    max_edges: int = ranged(0, 0)
    """Edge padding; 0 = max_nodes * (max_out_degree + 1)."""
    bridges: str = choice("useful", "off", "useful", "all")
    """A task already served (by any satellite) stays selectable at zero reward as a bridge (the verifier checks
    the slew between consecutive observations only): 'useful' when, from its node, some unserved task of the pass
    starts earlier than it can directly; 'all' always; 'off' never."""
    fleets: tuple[str, ...] = ()
    """Fleet directories (eosp generate --fleet) or aeossp case directories; environment copies share them out by
    worker index.  Empty: a small generated fleet."""
    seed: int = ranged(0, 0)
    """Seed of the fleet draws (combined with the worker and vector index)."""
    max_cached_fleets: int = ranged(8, 1)
    """Prepared fleets each environment copy keeps in memory."""

    def __post_init__(self) -> None:
        validate_fields(self)  # built in code, as a library user does: the same checks as a command line's


@dataclass
class ModelConfig:
    """The GNN agent (models/agent.py).  Presets: MODEL_PRESETS."""

    hidden_dim: int = ranged(64, 1, 1024)
    """Width of node and edge embeddings and of every GNN layer's output."""
    n_layers: int = ranged(10, 1, 64)
    """Number of GATv2 layers (each: 4-head attention, an MLP back to hidden_dim, a residual)."""
    heads: int = ranged(4, 1, 32)
    n_values: int = ranged(1, 1, 64)
    """Outputs of the value head: 1, or one per priority class for the lexicographic reward."""
    value_scale: float = ranged(0.0, 0.0)
    """The value head's output is multiplied by this (and the value loss divided by its square), so
    that returns of tens are learned as numbers of order 1; 0 = estimate it from random episodes."""


MODEL_PRESETS: dict[str, dict[str, Any]] = {
    # the paper's configuration
    "reference": {"hidden_dim": 64, "n_layers": 10, "heads": 4},
    # what trains in minutes on 2 CPU cores
    "cpu": {"hidden_dim": 32, "n_layers": 3, "heads": 2},
}


@dataclass
class TrainConfig:
    """PPO training (jobs/train.py)."""

    train_data: str = "data/demo/train"
    """Shard directory (or file) of the training instances."""
    val_data: str = "data/demo/val"
    """Held-out shards for periodic validation (greedy decoding); empty to skip."""
    iterations: int = ranged(10, 1)
    preset: str = "cpu"
    """Model preset applied before --model.* flags: 'cpu' or 'reference' (the paper's 64 x 10)."""
    num_env_runners: int = ranged(1, 0)
    """Rollout workers; each owns its envs over its own subset of the shards."""
    num_envs_per_env_runner: int = ranged(4, 1)
    """Environments each runner steps together: one batched network call acts for all of them (2 -> 4 made a
    runner's sampling 1.4 -> 0.8 s per 512 steps at 100 acquisitions, docs/benchmarks.md)."""
    rollout_values: bool = True
    """GAE's values come from the runners' own forward pass (the sampling weights, as in PPO's reference
    implementation) instead of a second pass over the whole batch in the learner (a tenth of its time); only each
    episode chunk's bootstrap observation is evaluated in the learner.  false: RLlib's learner-side pass."""
    overlap_sampling: bool = True
    """Sample the next batch while the learner updates on this one (training/overlap.py): the runners and
    the learner work at once; each batch is sampled with the weights of the previous update (a lag of one
    iteration).  Learned as well per env step as plain PPO on 3 seeds, 1.5x the env steps/s (docs/benchmarks.md);
    false: RLlib's PPO (sample, then learn)."""
    env_runner_resource: str = ""
    """A custom Ray resource each env runner requests one unit of, e.g. to place them on the nodes started
    with `ray start --resources '{"NAME": k}'`; empty: anywhere."""
    num_gpus_per_learner: float = ranged(0.0, 0)
    """GPUs per learner; >0 needs a GPU visible to Ray.  The learner runs in the driver (num_learners=0)."""
    train_batch_size: int = ranged(512, 1)
    """Environment steps collected per iteration."""
    minibatch_size: int = ranged(128, 1)
    num_epochs: int = ranged(4, 1)
    lr: float = ranged(3e-4, 0, lo_open=True)
    gamma: float = ranged(1.0, 0, 1)
    """Undiscounted, as in the paper."""
    gae_lambda: float = 0.95
    clip_param: float = 0.2
    entropy_coeff: float = 0.01
    vf_loss_coeff: float = 0.5
    grad_clip: float = 10.0
    validate_every: int = 5
    """Iterations between validations (and always after the last one)."""
    checkpoint_every: int = 5
    run_dir: str = "runs"
    """Where runs keep checkpoints and plots: RUN_DIR/RUN_NAME/."""
    run_name: str = ""
    """Name of the run; empty: a timestamp.  --resume continues the run of this name."""
    resume: bool = False
    overwrite: bool = False
    """Replace an existing run of this name (only one eosp wrote); without it, an existing run is refused."""
    time_budget: float = ranged(0.0, 0)
    """Make the iteration that starts past this many seconds of training the last one (0: no limit)."""
    init_checkpoint: str = ""
    """Start from this agent checkpoint (e.g. an imitation run's checkpoints/best): its model configuration
    replaces --model.*; empty: random initialization."""
    seed: int = 0
    mlflow_uri: str = ""
    """MLflow tracking URI; empty: sqlite database mlflow.db in the working directory (absolute path)."""
    experiment: str = "eosp"


@dataclass
class RunConfig:
    """Everything a training run uses; recorded with every run."""

    env: EnvConfig = field(default_factory=EnvConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class FleetTrainConfig(TrainConfig):
    """PPO fine-tuning of the fleet policy (jobs/train_fleet.py): the constellation environment on multi-agent env
    runners, every satellite acting with one shared module.  train_data: fleet directories (or directories of them)
    that the env runners share out; val_data: a demo set of held-out fleets (jobs/build_fleet_demos.py)."""

    train_data: str = "data/demos/train"
    """A demo set (jobs/build_fleet_demos.py): its fleets are the training fleets, which the env runners share out
    by index (never the evaluation splits)."""
    val_data: str = "data/demos/val"
    """A demo set of held-out fleets (greedy decoding against the fleet solver, the fleet greedy and the
    features-only decoder); empty to skip."""
    overlap_sampling: bool = False
    """Not for fleets (multi-agent episodes): RLlib's PPO (sample, then learn)."""
    experiment: str = "eosp-fleet"


@dataclass
class FleetRunConfig:
    """Everything a fleet PPO run uses; recorded with every run (jobs/train_fleet.py)."""

    env: FleetEnvConfig = field(default_factory=FleetEnvConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: FleetTrainConfig = field(default_factory=FleetTrainConfig)
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class PretrainConfig:
    """Everything an imitation run uses; recorded with every run (jobs/pretrain.py)."""

    env: EnvConfig = field(default_factory=EnvConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    imitation: ImitationConfig = field(default_factory=ImitationConfig)
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class FleetImitationConfig(ImitationConfig):
    """Imitation of the fleet solver by the fleet policy (jobs/pretrain_fleet.py).  The demonstrations carry one
    action per decision (the fleet solver's schedule replayed), no action values: regret_coeff, set_tolerance and
    dagger_beam do not apply (left at their defaults)."""

    train_data: tuple[str, ...] = ("data/demos/train",)
    """Demo sets of training fleets (jobs/build_fleet_demos.py)."""
    val_data: str = "data/demos/val"
    """A demo set of held-out fleets: greedy decoding against the fleet solver's schedules, the fleet greedy and the
    features-only decoder; empty: none."""
    dagger_instances: int = ranged(4, 1)
    """Training fleets on which the policy plays a partial day per DAgger round (the fleet solver completes it)."""
    dagger_time_limit: float = ranged(20.0, 0, WEEK_S, lo_open=True)
    """Seconds of fleet-solver search completing each DAgger day from the policy's partial schedule."""
    experiment: str = "eosp-fleet-imitation"


@dataclass
class FleetPretrainConfig:
    """Everything a fleet imitation run uses; recorded with every run (jobs/pretrain_fleet.py)."""

    env: FleetEnvConfig = field(default_factory=FleetEnvConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    imitation: FleetImitationConfig = field(default_factory=FleetImitationConfig)
    ray: RayConfig = field(default_factory=RayConfig)


@dataclass
class EvalConfig:
    """Solvers over a test set (jobs/evaluate.py)."""

    data: tuple[str, ...] = ("data/demo/val",)
    """Data set directories or shard files; instances are grouped by size in the report."""
    solvers: tuple[str, ...] = ("greedy", "ramp")
    """Any of: random, greedy, ramp, exact, lns, policy, mcts, sample, beam."""
    mode: str = choice("utility", "utility", "unitary")
    """'utility' or 'unitary' (count acquisitions)."""
    time_limit: float = ranged(60.0, 0, WEEK_S, lo_open=True)
    """Seconds per instance for the searching solvers (ramp, exact, lns)."""
    search_time: float = ranged(0.0, 0, WEEK_S)
    """Seconds of search per instance for the learned searches (sample, beam); 0: no limit (one round of
    samples, the whole beam)."""
    samples: int = 16
    """Episodes per batched round of the sample solver."""
    beam_width: int = 4
    """Partial schedules kept by the beam solver."""
    polish: bool = True
    """Learned searches (sample, beam, mcts): polish every complete schedule met (insert and swap moves)."""
    refine: float = ranged(0.75, 0.0, 1.0)
    """Learned searches with a time limit: the share of it spent refining the best schedule (ruin and recreate)."""
    windows: bool = True
    """Learned searches, while refining: also re-plan windows of consecutive acquisitions (eosp.planning.windows)."""
    window_graph: str = choice("pruned", "pruned", "unpruned")
    """Learned searches: the arcs a window's label sweep looks at, the pruned graph's or the unpruned graph's."""
    checkpoint: str = ""
    """Agent checkpoint for the policy, mcts, sample and beam solvers; empty: the shipped pretrained model of --mode."""
    budgets: tuple[int, ...] = ranged((0, 10, 100, 1000), 0)
    """MCTS simulations per decision (mcts solver only)."""
    out: str = "runs/eval"
    """Directory of the results: results.parquet, report.md, schedules/.  A rerun with the same settings resumes
    a killed evaluation; a finished one is replaced only with --overwrite; a directory eosp did not write is
    refused."""
    overwrite: bool = False
    """Replace the finished evaluation in --out (only one eosp wrote)."""
    save_schedules: bool = True
    html_reports: int = ranged(3, 0)
    """Write the HTML report of `eosp report` (map, timeline, roll/pitch, summary of every solver's schedule) for
    the first N instances, in OUT/reports/, and log them to MLflow; 0 for none."""
    mlflow_uri: str = ""
    experiment: str = "eosp-eval"


@dataclass
class TuneConfig:
    """Ray Tune sweep over the architecture and the learning rate (jobs/tune.py)."""

    name: str = "sweep"
    """Sweep name: runs in RUN_DIR/tune/NAME, one MLflow parent run of that name (a plain name, no '/')."""
    hidden_dims: tuple[int, ...] = ranged((16, 32), 1, 1024)
    n_layers: tuple[int, ...] = ranged((2, 3), 1, 64)
    lrs: tuple[float, ...] = ranged((1e-3,), 0.0, 1.0, lo_open=True)
    num_samples: int = ranged(1, 1)
    """Repeats of the grid (with different seeds)."""
    metric: str = "val/policy_mean"
    """Reported metric the scheduler and the best-trial choice maximize."""
    grace_period: int = ranged(2, 1)
    """ASHA: iterations every trial runs before it can be stopped."""
    cpus_per_trial: int = ranged(1, 1)
