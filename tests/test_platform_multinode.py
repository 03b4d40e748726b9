"""Two Ray nodes on this machine: env runners placed on the second one by a custom resource.

scripts/platform-up.sh starts the Ray head (1 CPU), the MLflow server and, with
EOSP_RAY_WORKER_NODES=1, a second Ray node (its own `ray start --address HEAD`, process group
and temp dir) offering 1 CPU and the custom resource `eosp_runner`.  A training job submitted
with `--train.env-runner-resource eosp_runner` must run its env runner on that node and log its
run to the MLflow server; asking for more env runners than the nodes offering the resource can
hold is refused in one line.  platform-down.sh stops both nodes.
"""

from __future__ import annotations

import json
import time

import pytest

from tests.test_platform import iterations_logged, running_platform, submit, wait

pytestmark = pytest.mark.platform

RESOURCE = "eosp_runner"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with running_platform(tmp_path_factory.mktemp("multinode"), EOSP_RAY_NUM_CPUS="1", EOSP_RAY_WORKER_NODES="1",
                          EOSP_RAY_WORKER_CPUS="1",
                          EOSP_RAY_WORKER_RESOURCES=json.dumps({RESOURCE: 1})) as p:
        yield p


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    from eosp.shards.io import write_shard
    from tests.conftest import generated

    d = tmp_path_factory.mktemp("multinode-data")  # an absolute path both nodes see
    write_shard(d / "train" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(3)])
    write_shard(d / "val" / "shard-0.parquet", [generated("uniform", 12, s) for s in range(100, 102)])
    return d


def states(p):
    from ray.util.state import StateApiClient

    return StateApiClient(address=p.dashboard, headers={"Authorization": f"Bearer {p.token}"})


def nodes(p):
    from ray.util.state.common import ListApiOptions, StateResource

    return states(p).list(StateResource.NODES, options=ListApiOptions(filters=[("state", "=", "ALIVE")], detail=True),
                          raise_on_missing_output=False)


def test_second_node_joins_on_the_loopback_and_offers_the_resource(cluster):
    import psutil

    p = cluster
    (node,) = p.state["ray"]["worker_nodes"]
    assert node["resources"] == {RESOURCE: 1} and node["name"] in p.state["services"]
    alive = nodes(p)
    assert sorted(n.is_head_node for n in alive) == [False, True]
    (head,) = [n for n in alive if n.is_head_node]
    (second,) = [n for n in alive if not n.is_head_node]
    assert head.resources_total["CPU"] == 1 and RESOURCE not in head.resources_total
    assert second.resources_total["CPU"] == 1 and second.resources_total[RESOURCE] == 1
    assert second.node_ip == "127.0.0.1"
    # the second node's processes are the platform's, and listen on the loopback only, like the head's
    exposed = {}
    for pid in p.processes():
        try:
            for c in psutil.Process(pid).net_connections(kind="inet"):
                if c.status == psutil.CONN_LISTEN and c.laddr.ip not in ("127.0.0.1", "::ffff:127.0.0.1", "::1"):
                    exposed[c.laddr.port] = (pid, c.laddr.ip)
        except psutil.Error:
            pass
    assert not exposed, f"listening beyond the loopback: {exposed}"


def test_env_runner_runs_on_the_node_offering_the_resource(cluster, data):
    from ray.util.state.common import ListApiOptions, StateResource

    import mlflow

    p, n = cluster, 3
    (second,) = [node.node_id for node in nodes(p) if not node.is_head_node]
    t0 = time.monotonic()
    job = submit(p, data, "eosp-test-multinode", "multinode", n,
                 "--train.env-runner-resource", RESOURCE, "--train.num-env-runners", 1)
    status = wait(p, job)
    logs = p.jobs().get_job_logs(job)
    print(f"[platform] multi-node job {status} after {time.monotonic() - t0:.0f} s")
    assert status == "SUCCEEDED", logs[-4000:]
    assert [i for i, _ in iterations_logged(logs)] == list(range(1, n + 1)), logs[-4000:]

    # the env runner of this job ran on the second node
    job_id = p.jobs().get_job_info(job).job_id
    runners = [a for a in states(p).list(
        StateResource.ACTORS, options=ListApiOptions(filters=[("class_name", "=", "SingleAgentEnvRunner")],
                                                     detail=True), raise_on_missing_output=False)
        if a.job_id == job_id]
    assert len(runners) == 1, runners
    assert runners[0].node_id == second, (runners[0].node_id, second)
    assert runners[0].required_resources.get(RESOURCE) == 1 and runners[0].required_resources.get("CPU") == 1

    # the run and its metrics are on the MLflow server
    run_id = json.loads((data / "runs" / "multinode" / "run.json").read_text())["mlflow_run_id"]
    client = mlflow.tracking.MlflowClient(p.mlflow_uri)
    run = client.get_run(run_id)
    assert run.info.status == "FINISHED" and run.info.run_name == "multinode"
    assert run.data.params["train.env_runner_resource"] == RESOURCE and run.data.params["train.num_env_runners"] == "1"
    assert [m.step for m in client.get_metric_history(run_id, "perf/iteration_s")] == list(range(1, n + 1))
    assert all(m.value > 0 for m in client.get_metric_history(run_id, "perf/env_steps_per_s"))
    assert client.get_metric_history(run_id, "val/ratio_to_greedy")


def test_more_env_runners_than_the_resource_holds_is_refused(cluster, data):
    p = cluster
    job = submit(p, data, "eosp-test-multinode-refused", "refused", 2,
                 "--train.env-runner-resource", RESOURCE, "--train.num-env-runners", 2)
    status = wait(p, job, timeout=120)
    logs = p.jobs().get_job_logs(job)
    assert status == "FAILED", logs[-3000:]
    line = (f"train.py: error: --train.env-runner-resource {RESOURCE} --train.num-env-runners 2: each env runner takes 1 "
            f"{RESOURCE} and 1 CPU of the same node, and the nodes that offer {RESOURCE} have room for 1 "
            f"(resources: 2 CPU, 1 {RESOURCE} on 2 nodes); pass --train.num-env-runners 1 or fewer, or add nodes")
    assert line in logs.splitlines() and "Traceback" not in logs, logs[-3000:]
    assert not (data / "runs" / "refused").exists()
