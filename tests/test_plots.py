"""The trajectory plot: PNG and SVG, for generated and for foreign instances."""

from eosp.evaluation.plots import plot_trajectories
from eosp.instances.schedule import from_internal_nodes
from eosp.solvers.random_walk import RandomConfig, solve
from tests.conftest import generated
from tests.synthetic import synthetic_instance


def test_trajectory_plot(tmp_path):
    inst = generated("uniform", 12, 0)
    scheds = {f"walk{s}": from_internal_nodes(inst, solve(inst, RandomConfig(seed=s)).nodes) for s in range(2)}
    paths = plot_trajectories(inst, scheds, tmp_path / "traj")
    assert [p.suffix for p in paths] == [".png", ".svg"]
    assert all(p.stat().st_size > 5000 for p in paths)
    assert paths[1].read_text().count("<path") > 20


def test_plot_without_attitudes(tmp_path):
    inst = synthetic_instance(6, 3)
    paths = plot_trajectories(inst, {"walk": from_internal_nodes(inst, solve(inst).nodes)}, tmp_path / "t")
    assert paths[0].exists()
