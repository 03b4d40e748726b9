#!/usr/bin/env bash
# Start the local platform: a Ray head (dashboard + job server) and an MLflow tracking server,
# and optionally extra Ray nodes on this machine (EOSP_RAY_WORKER_NODES) to try placements.
#
#   scripts/platform-up.sh            # or: make platform-up
#   source .platform/env              # RAY_API_SERVER_ADDRESS, RAY_AUTH_MODE, MLFLOW_TRACKING_URI, ...
#   ray job submit --working-dir . --runtime-env platform/runtime-env.yaml -- python jobs/train.py \
#       --train.mlflow-uri "$MLFLOW_TRACKING_URI" ...
#   scripts/platform-down.sh          # or: make platform-down
#
# Each service runs in its own process group (setsid) so that platform-down.sh stops
# exactly these processes and never another Ray on the machine (`ray stop` would kill
# every Ray process of the machine, other users' local ray.init() sessions included).
# Every process also carries EOSP_PLATFORM_ID in its environment, which lets
# platform-down.sh find the ones Ray moves to other sessions (job drivers, workers).
#
# Everything listens on 127.0.0.1 unless EOSP_PLATFORM_HOST says otherwise.  Settings
# (environment variables, all optional):
#   EOSP_PLATFORM_DIR        state directory (pids, ports, logs, MLflow store)   [.platform]
#   EOSP_PLATFORM_HOST       address both services bind to                      [127.0.0.1]
#   EOSP_RAY_NUM_CPUS        CPUs the Ray head offers                           [2]
#   EOSP_RAY_NUM_GPUS        GPUs the Ray head offers (a GPU learner runs in the job's driver, on the head) [0]
#   EOSP_RAY_WORKER_NODES    extra Ray nodes started on this machine and joined to the head, each in its
#                            own process group and temp dir (STATE/ray-node-I.log) [0]
#   EOSP_RAY_WORKER_CPUS     CPUs each extra node offers                        [1]
#   EOSP_RAY_WORKER_RESOURCES  custom resources each extra node offers, as JSON, e.g. '{"eosp_runner": 1}'
#                            (jobs place their env runners there with --train.env-runner-resource) [none]
#   EOSP_RAY_PORT            Ray GCS port                                       [a free port]
#   EOSP_RAY_DASHBOARD_PORT  dashboard / job submission port                    [a free port]
#   EOSP_RAY_AUTH_MODE       Ray authentication: token or disabled              [token]
#   EOSP_RAY_OBJECT_STORE_BYTES  object store size                              [Ray's default]
#   EOSP_RAY_TEMP_DIR        Ray sessions and logs    [STATE/ray, or /tmp/eosp-ray-ID if STATE is long]
#   EOSP_MLFLOW_PORT         MLflow port                                        [a free port]
#   EOSP_MLFLOW_BACKEND_URI  MLflow backend store                 [sqlite:///STATE/mlflow/mlflow.db]
#   EOSP_MLFLOW_ARTIFACTS    MLflow artifact store (served by the server)       [STATE/mlflow/artifacts]
#   EOSP_MLFLOW_WORKERS      MLflow server workers                              [1]
#   EOSP_PLATFORM_TIMEOUT    seconds to wait for the services to be healthy     [180]
#   EOSP_PYTHON              the Python with the project installed              [.venv/bin/python]
set -euo pipefail

# shellcheck source=scripts/platform-common.sh
source "$(dirname "${BASH_SOURCE[0]}")/platform-common.sh"
HOST=${EOSP_PLATFORM_HOST:-127.0.0.1}
NUM_CPUS=${EOSP_RAY_NUM_CPUS:-2}
NUM_GPUS=${EOSP_RAY_NUM_GPUS:-0}
WORKERS=${EOSP_RAY_WORKER_NODES:-0}
WORKER_CPUS=${EOSP_RAY_WORKER_CPUS:-1}
WORKER_RESOURCES=${EOSP_RAY_WORKER_RESOURCES:-}
AUTH_MODE=${EOSP_RAY_AUTH_MODE:-token}
TIMEOUT=${EOSP_PLATFORM_TIMEOUT:-180}
MLFLOW_WORKERS=${EOSP_MLFLOW_WORKERS:-1}

BIN=$(cd "$(dirname "$PY")" && pwd)
RAY=$BIN/ray
MLFLOW=$BIN/mlflow
for exe in "$RAY" "$MLFLOW"; do
    [[ -x $exe ]] || { echo "platform-up: $exe not found (install the project: make install)" >&2; exit 2; }
done
case $AUTH_MODE in token|disabled) ;; *) echo "platform-up: EOSP_RAY_AUTH_MODE must be token or disabled" >&2; exit 2;; esac
for setting in EOSP_RAY_NUM_CPUS="$NUM_CPUS" EOSP_RAY_NUM_GPUS="$NUM_GPUS" EOSP_RAY_WORKER_NODES="$WORKERS" \
               EOSP_RAY_WORKER_CPUS="$WORKER_CPUS"; do
    [[ ${setting#*=} =~ ^[0-9]+$ ]] || { echo "platform-up: ${setting%%=*} must be a whole number, got '${setting#*=}'" >&2
                                         exit 2; }
done
if [[ -n $WORKER_RESOURCES ]] && ! "$PY" - "$WORKER_RESOURCES" <<'EOF'
import json, sys
try:
    r = json.loads(sys.argv[1])
except ValueError:
    r = None
ok = isinstance(r, dict) and all(
    isinstance(k, str) and k and k not in ("CPU", "GPU", "memory", "object_store_memory")
    and isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0 for k, v in r.items())
if not ok:
    print("platform-up: EOSP_RAY_WORKER_RESOURCES must be a JSON object of custom resource names and amounts, "
          f"e.g. '{{\"eosp_runner\": 1}}', got {sys.argv[1]!r}", file=sys.stderr)
sys.exit(0 if ok else 1)
EOF
then
    exit 2
fi
case $HOST in
    0.0.0.0|::|'') echo "platform-up: EOSP_PLATFORM_HOST must be one address of this machine (Ray advertises it)," \
                        "not a wildcard" >&2; exit 2;;
esac
# this platform is its own cluster: never attach to one named by the caller's environment
unset RAY_ADDRESS RAY_API_SERVER_ADDRESS

mkdir -p "$STATE"
STATE=$(cd "$STATE" && pwd)
# the state directory ignores itself: nothing in it is committed or uploaded with --working-dir
[[ -f $STATE/.gitignore ]] || printf '*\n' > "$STATE/.gitignore"

if [[ -f $STATE/platform.json ]]; then
    if "$PY" - "$STATE/platform.json" <<'EOF'
import json, os, sys
s = json.load(open(sys.argv[1]))
alive = []
for svc in s["services"].values():
    try:
        os.killpg(svc["pgid"], 0)
        alive.append(svc["pgid"])
    except OSError:
        pass
sys.exit(0 if alive else 1)
EOF
    then
        echo "platform-up: already running (state in $STATE/platform.json); run scripts/platform-down.sh first" >&2
        exit 1
    fi
    rm -f "$STATE/platform.json" "$STATE/env"
fi

# free ports on HOST, chosen together so that they differ (10 for the head and MLflow, 6 per extra
# node); explicit ones win
read -r -a PORTS < <("$PY" - "$HOST" $((10 + 6 * WORKERS)) <<'EOF'
import socket, sys
socks = []
for _ in range(int(sys.argv[2])):
    s = socket.socket(socket.AF_INET6 if ":" in sys.argv[1] else socket.AF_INET)
    s.bind((sys.argv[1], 0))
    socks.append(s)
print(" ".join(str(s.getsockname()[1]) for s in socks))
EOF
)
read -r P_GCS P_DASH P_MLFLOW P_CLIENT P_NM P_OM P_AGENT P_AGENT_GRPC P_METRICS P_RTENV <<<"${PORTS[*]:0:10}"
RAY_PORT=${EOSP_RAY_PORT:-$P_GCS}
DASH_PORT=${EOSP_RAY_DASHBOARD_PORT:-$P_DASH}
MLFLOW_PORT=${EOSP_MLFLOW_PORT:-$P_MLFLOW}

ID=$("$PY" -c 'import secrets; print(secrets.token_hex(6))')
if [[ -n ${EOSP_RAY_TEMP_DIR:-} ]]; then
    RAY_TMP=$EOSP_RAY_TEMP_DIR
elif (( ${#STATE} <= 30 )); then
    RAY_TMP=$STATE/ray
else  # Ray's Unix sockets (TEMP/session_DATE_PID/sockets/dash_MetricsHead) must stay under 107 bytes
    RAY_TMP=/tmp/eosp-ray-$ID
fi
MLFLOW_DIR=$STATE/mlflow
ARTIFACTS=${EOSP_MLFLOW_ARTIFACTS:-$MLFLOW_DIR/artifacts}
BACKEND=${EOSP_MLFLOW_BACKEND_URI:-sqlite:///$MLFLOW_DIR/mlflow.db}
mkdir -p "$RAY_TMP" "$MLFLOW_DIR"
[[ $ARTIFACTS == *://* ]] || mkdir -p "$ARTIFACTS"

case $HOST in
    127.*|localhost|::1) ;;
    *) echo "platform-up: WARNING: listening on $HOST: anyone who reaches it can use the MLflow server" \
            "(no authentication) and, with the Ray token, run code on this machine" >&2;;
esac

# Ray token authentication (on by default in Ray 2.60): make sure a token exists
if [[ $AUTH_MODE == token && -z ${RAY_AUTH_TOKEN:-} && -z ${RAY_AUTH_TOKEN_PATH:-} && ! -s $HOME/.ray/auth_token ]]; then
    "$PY" "$RAY" get-auth-token --generate >/dev/null
fi

export EOSP_PLATFORM_ID=$ID RAY_AUTH_MODE=$AUTH_MODE RAY_USAGE_STATS_ENABLED=0 OMP_NUM_THREADS=1
case $HOST in
    # Ray replaces a loopback --node-ip-address by the machine's address (and its gRPC servers then
    # listen on every interface) unless it runs in single-machine mode, which this variable selects
    127.*|localhost|::1) export RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0;;
esac
# on SIGTERM (platform-down), tear down at once instead of draining the node for 30 s
export RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S=${RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S:-0}
# MLflow 3 starts a job runner with seven consumer processes by default: not needed here
export MLFLOW_SERVER_ENABLE_JOB_EXECUTION=${MLFLOW_SERVER_ENABLE_JOB_EXECUTION:-false}
# job entry points run `python ...`: that must be the project's Python
export PATH=$BIN:$PATH

RAY_ARGS=(start --head --block --node-ip-address "$HOST" --port "$RAY_PORT" --num-cpus "$NUM_CPUS" --num-gpus "$NUM_GPUS"
    --include-dashboard=true --dashboard-host "$HOST" --dashboard-port "$DASH_PORT"
    --ray-client-server-port "$P_CLIENT" --node-manager-port "$P_NM" --object-manager-port "$P_OM"
    --dashboard-agent-listen-port "$P_AGENT" --dashboard-agent-grpc-port "$P_AGENT_GRPC"
    --metrics-export-port "$P_METRICS" --runtime-env-agent-port "$P_RTENV"
    --temp-dir "$RAY_TMP" --disable-usage-stats)
[[ -z ${EOSP_RAY_OBJECT_STORE_BYTES:-} ]] || RAY_ARGS+=(--object-store-memory "$EOSP_RAY_OBJECT_STORE_BYTES")

# `setsid` of a background job (not a process group leader) execs in place: $! is the leader.
# The console scripts run through $PY, not their shebang: a virtual environment copied from
# another one keeps the shebangs of the original, whose Python (and installed project) Ray
# would then give to every worker.
setsid "$PY" "$RAY" "${RAY_ARGS[@]}" >"$STATE/ray.log" 2>&1 </dev/null &
RAY_PID=$!
setsid "$PY" "$MLFLOW" server --host "$HOST" --port "$MLFLOW_PORT" --workers "$MLFLOW_WORKERS" \
    --backend-store-uri "$BACKEND" --artifacts-destination "$ARTIFACTS" --serve-artifacts \
    >"$STATE/mlflow.log" 2>&1 </dev/null &
MLFLOW_PID=$!

URL_HOST=$HOST
[[ $HOST == *:* ]] && URL_HOST="[$HOST]"
DASH_URL=http://$URL_HOST:$DASH_PORT
MLFLOW_URL=http://$URL_HOST:$MLFLOW_PORT

write_state() {  # STATE/platform.json (atomically); $1: the extra nodes started so far, a JSON list
    S_ID=$ID S_HOST=$HOST S_ROOT=$ROOT S_PY=$PY S_GCS=$URL_HOST:$RAY_PORT S_DASH=$DASH_URL S_CPUS=$NUM_CPUS \
    S_GPUS=$NUM_GPUS S_AUTH=$AUTH_MODE S_RAY_TMP=$RAY_TMP S_MLFLOW=$MLFLOW_URL S_BACKEND=$BACKEND \
    S_ARTIFACTS=$ARTIFACTS S_RAY_PID=$RAY_PID S_MLFLOW_PID=$MLFLOW_PID S_STATE=$STATE S_NODES=$1 "$PY" - <<'EOF'
import json, os
e = os.environ
nodes = json.loads(e["S_NODES"])
state = {
    "id": e["S_ID"], "host": e["S_HOST"], "root": e["S_ROOT"], "python": e["S_PY"],
    "ray": {"gcs_address": e["S_GCS"], "dashboard_url": e["S_DASH"], "num_cpus": int(e["S_CPUS"]),
            "num_gpus": int(e["S_GPUS"]), "auth_mode": e["S_AUTH"], "temp_dir": e["S_RAY_TMP"],
            "log": e["S_STATE"] + "/ray.log",
            "worker_nodes": [{k: v for k, v in n.items() if k != "pid"} for n in nodes]},
    "mlflow": {"tracking_uri": e["S_MLFLOW"], "backend_store_uri": e["S_BACKEND"],
               "artifacts_destination": e["S_ARTIFACTS"], "log": e["S_STATE"] + "/mlflow.log"},
    "services": {"ray": {"pid": int(e["S_RAY_PID"]), "pgid": int(e["S_RAY_PID"])},
                 "mlflow": {"pid": int(e["S_MLFLOW_PID"]), "pgid": int(e["S_MLFLOW_PID"])},
                 **{n["name"]: {"pid": n["pid"], "pgid": n["pid"]} for n in nodes}},
}
with open(e["S_STATE"] + "/platform.json.tmp", "w") as f:
    json.dump(state, f, indent=1)
EOF
    mv "$STATE/platform.json.tmp" "$STATE/platform.json"
}
write_state "[]"

# wait until both answer: MLflow /health, and the Ray job server lists jobs (with the token)
if ! "$PY" - "$DASH_URL" "$MLFLOW_URL" "$RAY_PID" "$MLFLOW_PID" "$TIMEOUT" <<'EOF'
import os, sys, time, urllib.request
dash, mlflow_url, ray_pid, mlflow_pid, timeout = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
from ray.job_submission import JobSubmissionClient
t0, ok = time.monotonic(), {"ray": False, "mlflow": False}
while not all(ok.values()):
    for name, pid in (("ray", ray_pid), ("mlflow", mlflow_pid)):
        try:
            os.kill(pid, 0)
        except OSError:
            print(f"platform-up: the {name} process exited", file=sys.stderr)
            sys.exit(1)
    if not ok["mlflow"]:
        try:
            ok["mlflow"] = urllib.request.urlopen(mlflow_url + "/health", timeout=2).read().strip() == b"OK"
        except OSError:
            pass
    if not ok["ray"]:
        try:
            JobSubmissionClient(dash).list_jobs()
            ok["ray"] = True
        except Exception:
            pass
    if time.monotonic() - t0 > timeout:
        print(f"platform-up: not healthy after {timeout:.0f} s: {ok}", file=sys.stderr)
        sys.exit(1)
    time.sleep(0.5)
print(f"platform-up: healthy after {time.monotonic() - t0:.1f} s")
EOF
then
    for log in ray mlflow; do echo "--- $STATE/$log.log (end)" >&2; tail -n 30 "$STATE/$log.log" >&2 || true; done
    env -u EOSP_PLATFORM_ID "$ROOT/scripts/platform-down.sh" >&2 || true
    exit 1
fi

# Extra nodes on this machine, joined to the head: a second `ray start --address HEAD` each, in its own
# process group and temp dir.  On the loopback, `ray start` refuses a second node in single-machine mode
# and, in cluster mode, swaps the loopback addresses it is given for the machine's (where the head does
# not listen, and its own servers would then listen on every interface): this launcher runs it in cluster
# mode with the addresses kept as given, so the extra nodes listen on the loopback like the head.
LOOPBACK_NODE='import sys
from ray._private import services
from ray.scripts.scripts import main
services.resolve_ip_for_localhost = lambda host: services.get_localhost_ip() if host == "localhost" else host
sys.argv[0] = "ray"
main()'
NODES="[]" NODE_PIDS=()
for ((i = 1; i <= WORKERS; i++)); do
    o=$((10 + 6 * (i - 1)))
    NODE_TMP=$RAY_TMP/node$i  # short: Ray's Unix socket paths under it must stay under 107 bytes
    mkdir -p "$NODE_TMP"
    NODE_ARGS=(start --block --address "$URL_HOST:$RAY_PORT" --node-ip-address "$HOST" --num-cpus "$WORKER_CPUS"
        --num-gpus 0 --node-manager-port "${PORTS[o]}" --object-manager-port "${PORTS[o + 1]}"
        --dashboard-agent-listen-port "${PORTS[o + 2]}" --dashboard-agent-grpc-port "${PORTS[o + 3]}"
        --metrics-export-port "${PORTS[o + 4]}" --runtime-env-agent-port "${PORTS[o + 5]}"
        --temp-dir "$NODE_TMP" --disable-usage-stats)
    [[ -z $WORKER_RESOURCES ]] || NODE_ARGS+=(--resources "$WORKER_RESOURCES")
    [[ -z ${EOSP_RAY_OBJECT_STORE_BYTES:-} ]] || NODE_ARGS+=(--object-store-memory "$EOSP_RAY_OBJECT_STORE_BYTES")
    if [[ ${RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER:-} == 0 ]]; then
        RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=1 setsid "$PY" -c "$LOOPBACK_NODE" "${NODE_ARGS[@]}" \
            >"$STATE/ray-node-$i.log" 2>&1 </dev/null &
    else
        setsid "$PY" "$RAY" "${NODE_ARGS[@]}" >"$STATE/ray-node-$i.log" 2>&1 </dev/null &
    fi
    NODE_PIDS+=("$!")
    NODES=$("$PY" -c 'import json, sys; n = json.loads(sys.argv[1]); n.append({"name": sys.argv[2], "pid": int(sys.argv[3]),
"num_cpus": int(sys.argv[4]), "resources": json.loads(sys.argv[5] or "{}"), "temp_dir": sys.argv[6], "log": sys.argv[7]})
print(json.dumps(n))' "$NODES" "ray-node-$i" "$!" "$WORKER_CPUS" "$WORKER_RESOURCES" "$NODE_TMP" \
        "$STATE/ray-node-$i.log")
done
if (( WORKERS > 0 )); then
    write_state "$NODES"
    # wait until every extra node is alive in the cluster
    if ! "$PY" - "$DASH_URL" "$NODES" "$TIMEOUT" <<'EOF'
import json, os, sys, time
dash, nodes, timeout = sys.argv[1], json.loads(sys.argv[2]), float(sys.argv[3])
from ray.util.state import StateApiClient
from ray.util.state.common import ListApiOptions, StateResource
t0, client, alive = time.monotonic(), StateApiClient(address=dash), 0
while alive < 1 + len(nodes):
    for n in nodes:
        try:
            os.kill(n["pid"], 0)
        except OSError:
            print(f"platform-up: Ray node {n['name']} exited", file=sys.stderr)
            sys.exit(1)
    try:
        alive = len(client.list(StateResource.NODES, options=ListApiOptions(filters=[("state", "=", "ALIVE")]),
                                raise_on_missing_output=False))
    except Exception:
        pass
    if time.monotonic() - t0 > timeout:
        print(f"platform-up: {alive} of {1 + len(nodes)} Ray nodes alive after {timeout:.0f} s", file=sys.stderr)
        sys.exit(1)
    time.sleep(0.5)
print(f"platform-up: {len(nodes)} extra Ray node(s) joined after {time.monotonic() - t0:.1f} s")
EOF
    then
        for ((i = 1; i <= WORKERS; i++)); do
            echo "--- $STATE/ray-node-$i.log (end)" >&2; tail -n 30 "$STATE/ray-node-$i.log" >&2 || true
        done
        env -u EOSP_PLATFORM_ID "$ROOT/scripts/platform-down.sh" >&2 || true
        exit 1
    fi
fi

cat >"$STATE/env" <<EOF
# source this file to use the platform started by scripts/platform-up.sh
export RAY_API_SERVER_ADDRESS=$DASH_URL
export RAY_AUTH_MODE=$AUTH_MODE
export MLFLOW_TRACKING_URI=$MLFLOW_URL
EOF

echo "platform-up: Ray head    $DASH_URL  (GCS $URL_HOST:$RAY_PORT, $NUM_CPUS CPUs, $NUM_GPUS GPUs, auth $AUTH_MODE, pgid $RAY_PID)"
for ((i = 1; i <= WORKERS; i++)); do
    echo "platform-up: Ray node $i  $WORKER_CPUS CPUs${WORKER_RESOURCES:+, $WORKER_RESOURCES}  (log $STATE/ray-node-$i.log," \
         "pgid ${NODE_PIDS[i - 1]})"
done
cat <<EOF
platform-up: MLflow      $MLFLOW_URL  (backend $BACKEND, artifacts $ARTIFACTS, pgid $MLFLOW_PID)
platform-up: state in $STATE; use it with:  source $STATE/env
platform-up: submit:  ray job submit --working-dir . --runtime-env platform/runtime-env.yaml -- python jobs/train.py --train.mlflow-uri $MLFLOW_URL ...
EOF
