"""The options of the fleet kind's solvers (``eosp solve FLEET_DIR --solver greedy|fleet|fleet-policy|fleet-sample|
fleet-features``, jobs/solve_fleet.py)."""

from __future__ import annotations

from dataclasses import dataclass

from eosp.config import WEEK_S, choice, ranged
from eosp.solvers.base import UtilityConfig
from eosp.solvers.fleet_policy import DEFAULT_RULE, FEATURE_RULES

PASS_SOLVERS = ("greedy", "ramp", "exact")
LEARNED_PASS_SOLVERS = ("policy",)  # no model is trained on fleet passes yet: refused with one line


@dataclass
class GreedyConfig(UtilityConfig):
    """Options of the fleet greedy (each task once, by weight): one pass, deterministic."""

    NAME = "greedy"
    ONE_SHOT = True


@dataclass
class FleetConfig(UtilityConfig):
    """Options of the fleet solver (``eosp solve FLEET_DIR --solver fleet``)."""

    time_limit: float | None = ranged(60.0, 0, WEEK_S, lo_open=True, zero_unsets=True)
    seed: int = ranged(0, 0)
    """Seed of the large-neighbourhood moves."""
    pass_solver: str = choice("exact", *PASS_SOLVERS, *LEARNED_PASS_SOLVERS)
    """Single-pass solver of every pass: exact (optima, hence a proven Lagrangian bound), ramp or greedy (the
    conflict-free bound only); policy needs a model trained on fleet passes, which is not shipped yet."""
    rounds: int | None = ranged(None, 1)
    """Rounds: each a price round and the schedule recovered from it, then a large-neighbourhood move when that
    schedule is not better (the move alone once --price-step lp has its prices at L's minimum); a deterministic
    budget: the same schedule for a seed on any machine, with --time-limit 0 or one long enough.
    Unset: as many as the time limit allows."""
    pass_time_limit: float = ranged(5.0, 0, WEEK_S)
    """Seconds the exact solver may spend on one pass (its bound is used when it stops early)."""
    span_s: float = ranged(3600.0, 1)
    """Length of the time span freed by one large-neighbourhood move."""
    energy_bound: bool = False
    """Price the battery's energy windows in the Lagrangian bound (eosp.fleet.energy; valid either way).  Off by
    default: at the prices the rounds reach the windows are rarely overspent, and on test_hard/case_0005 the
    linear program's optimum gives them no weight (docs/results.md), so the search costs rounds for no bound."""
    energy_search: bool = True
    """With --energy-bound, move the energy windows' multipliers by line searches at each round's task prices
    (a window per satellite, the bound never raised by them) instead of subgradient steps."""
    energy_price: float = ranged(1.0, 0)
    """With --energy-bound, the share of the bound's energy prices (what a Wh is worth in each pass, from the
    battery's energy windows) that the schedules' pass problems pay (construction, coordinate descent, moves):
    0 leaves energy to the battery repair alone."""
    integer_energy: bool = True
    """The battery's energy windows as rows of the master's integer solution (--price-step lp): each pass
    schedule's energy with the slews between its observations, so that the packing is one the batteries nearly
    hold and the battery repair takes little out of it.  Schedules only; the bound is unchanged."""
    workers: int = ranged(1, 1, 256)
    """Processes solving the passes of a price round (forked from this one, the pass graphs shared)."""
    warm_start: str = choice("heuristic", "none", "heuristic", "learned")
    """Where the task prices start: none (0), heuristic (weight x (1 - 1/satellites that can serve the task)) or
    learned (the shipped price network over the task-opportunity graph, eosp.kinds.fleet.warmstart).  The
    default is the best by measurement (docs/results.md): at 200 satellites heuristic's WCR and gap at 60 s beat
    the other starts' at 600 s; on the aeossp cases at 10 s learned proves the lowest gap, heuristic the best WCR
    on average.  Round 0 also bounds with the ceiling prices (every contested task at its weight) whatever the
    start."""
    price_step: str = choice("lp", "uniform", "weighted", "lp")
    """The price step after each round: Polyak's subgradient step towards the best schedule, weighted (each task's
    price moves in proportion to the task's weight) or uniform (every price by the same amount per unit of its
    subgradient); or lp (column generation: the next prices from the duals of a linear program over the passes'
    schedules found so far, smoothed towards the prices of the lowest bound, eosp.kinds.fleet.master).
    lp falls back to weighted steps when its LP takes longer than a round's pass solves three rounds in a row (a
    200-satellite day); once its prices minimise the bound, one round takes the LP's best integer solution over
    its pass schedules as a schedule.
    Any prices give a valid bound: the rule changes how fast bound and schedules improve, never what the bound
    means.  lp is the default by measurement on the aeossp train split (docs/results.md): at 120 s a lower
    bound than weighted on 10 of 10 cases, the median gap 0.41% -> 0.26%, the same mean WCR."""
    price_model: str = ""
    """Directory of the price network used by --warm-start learned (prices.pt, prices.json from
    jobs/train_prices.py); empty: the shipped one."""

    NAME = "fleet"
    BUDGET = "rounds"

    def validate(self) -> None:
        super().validate()
        if self.price_model and self.warm_start != "learned":
            raise ValueError(f"price_model is the network of warm_start 'learned' (--warm-start learned "
                             f"--price-model DIR), not read with warm_start {self.warm_start!r}")


POLISHES = ("fill", "none")


@dataclass
class FleetPolicyConfig(UtilityConfig):
    """Options of the fleet policy's greedy decoding (``--solver fleet-policy``): one pass, deterministic."""

    checkpoint: str = ""
    """A fleet policy (jobs/pretrain_fleet.py, jobs/train_fleet.py: a checkpoint directory); empty: the shipped one
    (models/pretrained-agents/fleet).  Another observation layout or objective is refused in one line."""
    polish: str = choice("fill", *POLISHES)
    """Post-processing of the decoded schedule: 'fill' inserts the tasks it leaves unserved where they still fit
    (the fleet greedy's insertion by weight, then its battery repair; kept only when it serves more weight); 'none':
    the decode as is.  The raw decode's WCR is reported beside the result either way."""

    NAME = "fleet-policy"
    ONE_SHOT = True


@dataclass
class FleetSampleConfig(FleetPolicyConfig):
    """Options of batched sampling of the fleet policy (``--solver fleet-sample``): the greedy episode first, then
    rounds of sampled episodes in lockstep (one network call a step for all of them) until the time limit; the
    best kept, then post-processed."""

    time_limit: float | None = ranged(30.0, 0, WEEK_S, lo_open=True, zero_unsets=True)
    seed: int = ranged(0, 0)
    """Seed of the sampled episodes."""
    samples: int = ranged(16, 1, 1024)
    """Episodes per batched round (the first round's first one is the greedy episode; at most 1,024: the batch's
    observations are held at once)."""
    temperature: float = ranged(1.0, 0)
    """Softmax temperature of the sampled episodes (0: the argmax)."""

    NAME = "fleet-sample"
    ONE_SHOT = False


@dataclass
class FleetFeaturesConfig(UtilityConfig):
    """Options of the features-only decoder (``--solver fleet-features``): the fleet policy's decoder with a hand
    rule over the same observation features in place of the network (the ablation); one pass, deterministic."""

    rule: str = choice(DEFAULT_RULE, *FEATURE_RULES)
    """The linear rule over node features (eosp.solvers.fleet_policy.FEATURE_RULES); the default, the best on the
    training fleets (experiments/fleet_rules.py)."""
    polish: str = choice("fill", *POLISHES)
    """Post-processing, as fleet-policy's: 'fill' (the unserved tasks inserted where they fit, kept when it serves
    more) or 'none'; the raw decode's WCR is reported beside the result."""

    NAME = "fleet-features"
    ONE_SHOT = True
