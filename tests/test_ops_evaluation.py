"""The evaluation scenarios of learned planners (eosp/ops/evaluation_scenarios.json), fixed before any training:
the file is the one committed (its fingerprint), every scenario can be made from it, its aeossp fleets come from
the benchmark's evaluation splits, and a scenario made with one of its seeds is refused to training."""

from __future__ import annotations

import hashlib
from importlib.resources import files

import pytest

from eosp.errors import InputError
from eosp.fleet.aeossp import EVALUATION_SPLITS
from eosp.fleet.generate import FleetGenConfig, generate
from eosp.fleet.io import write_fleet
from eosp.fleet.opportunities import compute
from eosp.ops import scenario
from eosp.ops.evaluation import evaluation_scenarios, evaluation_seeds, refuse_evaluation_scenario
from eosp.ops.scenario import ScenarioConfig, make

# Changed only deliberately (a new evaluation set, said so in the commit): never to fit a result.
FINGERPRINT = "14d7ac59f3a70db6c190042acdb3287f7fa09b43bf09b6a6cb98e10209ecf963"


def test_the_evaluation_file_is_the_one_fixed_before_training():
    data = files("eosp.ops").joinpath("evaluation_scenarios.json").read_bytes()
    assert hashlib.sha256(data).hexdigest() == FINGERPRINT


def test_every_evaluation_scenario_names_what_makes_it():
    spec = evaluation_scenarios()
    names = [s["name"] for s in spec["scenarios"]]
    assert len(set(names)) == len(names) == 4 and len(evaluation_seeds()) == 4
    for s in spec["scenarios"]:
        ScenarioConfig(hours=s["hours"], seed=s["seed"])  # in range
        assert s["realizations"] >= 100
        fleet = s["fleet"]
        if "aeossp_case" in fleet:
            assert fleet["aeossp_case"].split("/")[0] in EVALUATION_SPLITS
        else:
            FleetGenConfig(**fleet["generate"])
    for p in spec["perturbed"]:
        ScenarioConfig(**p["options"])


@pytest.mark.parametrize("seed", [*sorted(evaluation_seeds())[:1], 3])
def test_a_scenario_with_an_evaluation_seed_is_refused_to_training(tmp_path, seed):
    f = generate(FleetGenConfig(satellites=2, tasks=20, hours=2.0, seed=1))
    write_fleet(f, compute(f), tmp_path / "fleet")
    make(str(tmp_path / "fleet"), ScenarioConfig(seed=seed), str(tmp_path / "scen"))
    scen = scenario.read(tmp_path / "scen")
    if seed in evaluation_seeds():
        with pytest.raises(InputError, match="evaluation scenario"):
            refuse_evaluation_scenario(scen, "--train-scenarios")
    else:
        refuse_evaluation_scenario(scen, "--train-scenarios")
