#!/usr/bin/env bash
# Stop the platform started by scripts/platform-up.sh (or make platform-up).
#
# Stops exactly what platform-up.sh started: each service's process group (the Ray head, the
# extra Ray nodes of EOSP_RAY_WORKER_NODES, the MLflow server: SIGTERM to its leader, then to
# the group, then SIGKILL, within EOSP_PLATFORM_GRACE seconds [10]), then any process left that
# carries this platform's EOSP_PLATFORM_ID in its environment (Ray job drivers and workers run
# in sessions of their own).  It never runs `ray stop`, which would kill
# every Ray process on the machine, other users' local ray.init() sessions included.
# The MLflow store (STATE/mlflow) and the logs are kept.
set -euo pipefail

# shellcheck source=scripts/platform-common.sh
source "$(dirname "${BASH_SOURCE[0]}")/platform-common.sh"
GRACE=${EOSP_PLATFORM_GRACE:-10}

if [[ ! -f $STATE/platform.json ]]; then
    echo "platform-down: nothing to stop (no $STATE/platform.json)"
    exit 0
fi

"$PY" - "$STATE/platform.json" "$GRACE" <<'EOF'
import json, os, signal, sys, time

state = json.load(open(sys.argv[1]))
grace = float(sys.argv[2])
marker = f"EOSP_PLATFORM_ID={state['id']}".encode()


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:  # the group id was reused by someone else's processes
        return False


def leader_is_ours(pid: int) -> bool:
    """The group leader, if still there, is the process we started (its environment has our marker)."""
    try:
        with open(f"/proc/{pid}/environ", "rb") as f:
            return marker in f.read().split(b"\0")
    except FileNotFoundError:
        return True  # leader gone, members may remain: the group id cannot be reused while they live
    except OSError:
        return False


def ancestors() -> set[int]:
    out, pid = set(), os.getpid()
    while pid > 1:
        out.add(pid)
        try:
            with open(f"/proc/{pid}/stat") as f:
                pid = int(f.read().rsplit(")", 1)[1].split()[1])
        except OSError:
            break
    return out


def marked() -> list[int]:
    """Processes that carry this platform's marker (job drivers and Ray workers included), not our callers."""
    out, mine = [], ancestors()
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) in mine:
            continue
        try:
            with open(f"/proc/{name}/environ", "rb") as f:
                if marker in f.read().split(b"\0"):
                    out.append(int(name))
        except OSError:
            pass
    return out


def wait_groups(groups: dict, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and any(group_alive(g) for g in groups.values()):
        time.sleep(0.2)


# 1. SIGTERM to each leader (`ray start --block` stops its own processes in order; mlflow its workers)
groups = {}
for name, svc in state["services"].items():
    if group_alive(svc["pgid"]) and leader_is_ours(svc["pid"]):
        groups[name] = svc["pgid"]
        try:
            os.kill(svc["pid"], signal.SIGTERM)
        except ProcessLookupError:
            pass
wait_groups(groups, grace / 2)
# 2. SIGTERM to whatever is left in the groups, 3. then SIGKILL
for g in groups.values():
    try:
        os.killpg(g, signal.SIGTERM)
    except ProcessLookupError:
        pass
wait_groups(groups, grace / 2)
for name, g in groups.items():
    if group_alive(g):
        print(f"platform-down: {name} still running after {grace:.0f} s: SIGKILL", file=sys.stderr)
        try:
            os.killpg(g, signal.SIGKILL)
        except ProcessLookupError:
            pass
# stragglers in other sessions: SIGTERM, then SIGKILL
left = marked()
for pid in left:
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        pass
deadline = time.monotonic() + min(grace, 5.0)
while left and time.monotonic() < deadline:
    time.sleep(0.2)
    left = marked()
for pid in left:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
time.sleep(0.2 if left else 0)
if marked():
    print(f"platform-down: processes still running: {marked()}", file=sys.stderr)
    sys.exit(1)
print(f"platform-down: stopped {', '.join(groups) or 'nothing (already stopped)'}"
      + (f" and {len(left)} other process(es)" if left else ""))
EOF
mv "$STATE/platform.json" "$STATE/platform.last.json"
rm -f "$STATE/env"
