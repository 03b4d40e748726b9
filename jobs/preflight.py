"""Checks every job makes before any work: where its outputs go, and whether MLflow answers.

* A job submitted with ``ray job submit --working-dir .`` runs in Ray's temporary,
  unpacked copy of the working dir (``.../runtime_resources/working_dir_files/...``
  under the Ray session directory), which is deleted with the session.  A relative
  run or output directory would land there, where nobody finds it: such a job
  refuses it with one line naming the absolute path to pass.
* An MLflow tracking server that does not answer is reported in one line at the
  start, not after an hour of training.
* A training the Ray cluster cannot run (more env runners than CPUs, a GPU learner
  without a GPU, env runners placed on a custom resource no node offers) is refused in
  one line once Ray is up, before RLlib builds anything (it would wait forever for the
  env runners, or fail deep inside).
"""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from collections.abc import Mapping, Sequence
from pathlib import Path

from eosp.errors import Refused

UPLOADED_MARKER = ("runtime_resources", "working_dir_files")


def uploaded_working_dir(cwd: str | Path | None = None) -> Path | None:
    """The root of Ray's unpacked copy of an uploaded working dir when `cwd` (default: the current
    directory) is inside one, else None."""
    parts = Path(cwd if cwd is not None else os.getcwd()).resolve().parts
    for i in range(len(parts) - 1):
        if parts[i] == UPLOADED_MARKER[0] and parts[i + 1] == UPLOADED_MARKER[1]:
            return Path(*parts[:i + 3]) if len(parts) > i + 2 else Path(*parts[:i + 2])
    return None


def require_findable(path: str, flag: str, example: str = "/shared") -> None:
    """Refused (one line, exit status 2) when `path` is relative and the job runs from an uploaded working dir."""
    root = uploaded_working_dir()
    if root is None or Path(path).is_absolute():
        return
    raise Refused(f"{flag} {path!r} is relative, and this job runs in Ray's temporary copy of the "
                  f"working dir ({root}), deleted with the session: pass an absolute path, e.g. "
                  f"{flag} {example.rstrip('/')}/{Path(path).as_posix()}")


def check_mlflow(uri: str, flag: str = "--mlflow-uri", timeout: float = 5.0) -> None:
    """Refused (one line, exit status 2) when the tracking URI cannot be used: an HTTP server that does not answer,
    or (from an uploaded working dir) the default database inside Ray's temporary copy."""
    if not uri:
        if uploaded_working_dir() is not None:
            raise Refused(f"no {flag} given, and the default mlflow.db would be written in Ray's temporary "
                          "copy of the working dir: pass a tracking server (http://...) or "
                          f"{flag} sqlite:////shared/mlflow.db")
        return
    scheme = uri.partition("://")[0].lower() if "://" in uri else ""
    if scheme not in TRACKING_SCHEMES:
        what = f"scheme {scheme!r}" if scheme else "no scheme"
        raise Refused(f"{flag} {uri}: not a tracking URI MLflow can use ({what}; use http(s)://HOST:PORT, "
                      f"sqlite:///PATH/mlflow.db or a database URI: {', '.join(TRACKING_SCHEMES)})")
    if scheme == "sqlite":
        _check_sqlite(uri, flag)
        return
    if not uri.startswith(("http://", "https://")):
        return
    try:
        with urllib.request.urlopen(uri.rstrip("/") + "/health", timeout=timeout) as resp:
            resp.read(64)
    except urllib.error.HTTPError:
        return  # it answered (an old server without /health, or a proxy): let MLflow judge
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        raise Refused(f"MLflow tracking server {uri} unreachable ({reason}): start it, or pass another "
                      f"{flag} (e.g. sqlite:///$PWD/mlflow.db)") from None


TRACKING_SCHEMES = ("http", "https", "sqlite", "postgresql", "mysql", "mssql", "databricks")
SQLITE_MAGIC = b"SQLite format 3\x00"


def _check_sqlite(uri: str, flag: str) -> None:
    """A sqlite store: its file, when it exists, must be an SQLite database (never a user's other file), and its
    directory writable."""
    from eosp.jobs.tracking import sqlite_path

    db = sqlite_path(uri)
    if db is None or not db.name:
        raise Refused(f"{flag} {uri}: a sqlite URI names a database file (sqlite:////abs/path/mlflow.db)")
    if db.exists():
        try:
            with open(db, "rb") as fh:
                head = fh.read(len(SQLITE_MAGIC))
        except OSError as exc:
            raise Refused(f"{flag} {uri}: cannot read {db} ({exc.strerror or exc})") from None
        if head and head != SQLITE_MAGIC:
            raise Refused(f"{flag} {uri}: {db} exists and is not an SQLite database: refusing to use it")
        return
    for parent in db.resolve().parents:
        if parent.exists():
            if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
                raise Refused(f"{flag} {uri}: cannot create {db} (no writable directory {parent})")
            return


# --------------------------------------------------------------------------- what the Ray cluster offers

_NOT_SHOWN = ("memory", "object_store_memory")


def _describe(nodes: Sequence[Mapping[str, float]]) -> str:
    """'3 CPU, 1 eosp_runner on 2 nodes': the cluster's schedulable resources (memory and node labels left out)."""
    totals: dict[str, float] = {}
    for node in nodes:
        for k, v in node.items():
            if k not in _NOT_SHOWN and not k.startswith(("node:", "accelerator_type:")):
                totals[k] = totals.get(k, 0.0) + float(v)
    order = sorted(totals, key=lambda k: (k not in ("CPU", "GPU"), k != "CPU", k))
    parts = ", ".join(f"{totals[k]:g} {k}" for k in order) or "nothing"
    return f"{parts} on {len(nodes)} node{'s' if len(nodes) != 1 else ''}"


def cluster_problem(train, nodes: Sequence[Mapping[str, float]], driver_gpus: int | None = None) -> str | None:
    """Why the Ray cluster cannot run this training (one line), or None when it can.

    `train` is a :class:`eosp.config.TrainConfig`; `nodes` the total resources of each alive node
    (``ray.nodes()[i]["Resources"]``; a single ``ray.cluster_resources()`` dict stands for the whole
    cluster as one node); `driver_gpus` the CUDA devices the driver process sees (None: not checked).
    What RLlib asks for: every env runner 1 CPU (+ 1 unit of `env_runner_resource` on the same node);
    the learner, in the driver (num_learners=0), `num_gpus_per_learner` GPUs of the driver's node.
    """
    n = train.num_env_runners
    where = _describe(nodes)

    def total(key: str) -> float:
        return sum(float(node.get(key, 0.0)) for node in nodes)

    if train.num_gpus_per_learner > 0:
        flag = f"--train.num-gpus-per-learner {train.num_gpus_per_learner:g}"
        gpus = total("GPU")
        if gpus <= 0:
            return f"{flag}: this Ray cluster has no GPU (resources: {where})"
        if gpus < train.num_gpus_per_learner:
            return f"{flag}: this Ray cluster has {gpus:g} GPU (resources: {where})"
        if driver_gpus == 0:
            return (f"{flag}: the learner runs in the driver (num_learners=0), which sees no CUDA device "
                    f"(resources: {where}): run the driver on a node with a GPU and a CUDA build of torch")
    name = train.env_runner_resource
    if name and n == 0:
        return (f"--train.env-runner-resource {name} places env runners, but --train.num-env-runners is 0 (sampling "
                "in the driver): pass --train.num-env-runners 1 or more")
    cpus = int(sum(int(float(node.get("CPU", 0.0))) for node in nodes))
    if n > cpus:
        return (f"--train.num-env-runners {n}: each env runner takes 1 CPU and this Ray cluster has {cpus} "
                f"(resources: {where}); pass --train.num-env-runners {cpus} or fewer, or add nodes")
    if name:
        if total(name) <= 0:
            return (f"--train.env-runner-resource {name}: no node of this Ray cluster offers it (resources: {where});"
                    f" start nodes with: ray start --address HEAD:PORT --resources '{{\"{name}\": K}}'")
        # each runner needs 1 CPU and 1 unit of the resource on the same node
        room = sum(min(int(float(node.get("CPU", 0.0))), int(float(node.get(name, 0.0)))) for node in nodes)
        if n > room:
            return (f"--train.env-runner-resource {name} --train.num-env-runners {n}: each env runner takes 1 {name} "
                    f"and 1 CPU of the same node, and the nodes that offer {name} have room for {room} "
                    f"(resources: {where}); pass --train.num-env-runners {room} or fewer, or add nodes")
    return None


def require_cluster_fits(train, nodes: Sequence[Mapping[str, float]], driver_gpus: int | None = None) -> None:
    """Refused (one line, exit status 2) when the Ray cluster cannot run this training: see :func:`cluster_problem`.
    Called after Ray is initialised and before the algorithm is built (which would hang waiting for the
    env runners, or fail deep inside RLlib)."""
    problem = cluster_problem(train, nodes, driver_gpus)
    if problem:
        raise Refused(problem)


def ray_nodes() -> list[dict[str, float]]:
    """The total resources of each alive node of the Ray cluster this process is attached to."""
    import ray

    return [dict(node["Resources"]) for node in ray.nodes() if node.get("Alive")]


# --------------------------------------------------------------------------- data sets and run directories, before any service

def require_data(paths, flag: str) -> None:
    """InputError (one line, exit 2 through the job's error path) unless every path of `paths` (one or a tuple)
    is a data set: a shard file, or a directory of shards written by eosp.  Checked from the files' headers
    before Ray or MLflow start; an instance directory is told apart (it needs ``eosp import`` first)."""
    from eosp.errors import InputError
    from eosp.shards.io import is_shard

    for path in (paths,) if isinstance(paths, (str, Path)) else paths:
        p = Path(path)
        where = f"{flag} {path}"
        if not p.exists():
            raise InputError(where, "not found (a data set directory of shards, or a shard file)")
        if p.is_dir() and all((p / f).is_file() for f in ("acquisitions.parquet", "nodes.parquet", "arcs.parquet")):
            raise InputError(where, "is an instance directory, not a data set of shards: import it first "
                                    "(eosp import DIR --out SHARD.parquet) and pass the shard")
        files = [p] if p.is_file() else sorted(p.glob("*.parquet"))
        if not files:
            raise InputError(where, "no shard (*.parquet) in this directory")
        foreign = next((f for f in files if not is_shard(f)), None)
        if foreign is not None:
            raise InputError(foreign, f"not a shard written by eosp (given as {flag})")


def is_run_dir(path: Path, kind: str = "run") -> bool:
    """Whether `path` is a run directory eosp wrote: its mark (eosp.ownership), or, for runs written before the
    marks, the state file only eosp writes there (train's run.json, pretrain's history.json)."""
    from eosp.ownership import kind_of

    if kind_of(path) == kind:
        return True
    if kind != "run":
        return False
    for name, keys in (("run.json", {"config", "mlflow_run_id", "iteration"}), ("history.json", {"config", "history"})):
        try:
            state = json.loads((path / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(state, dict) and keys <= set(state):
            return True
    return False


def require_run_dir(path: str | Path, kind: str, prefix: str, resume: bool = False, overwrite: bool = False) -> Path:
    """Refuse, before any service starts or any directory is created, a run directory that eosp must not write:
    an existing one eosp did not write (never written into), or one it did unless the job resumes it (`resume`)
    or replaces it (`overwrite`).  `prefix`: the flags' ('--train': --train.run-dir, --train.overwrite,
    --train.resume).  A one-line InputError naming the flag."""
    from eosp.errors import InputError
    from eosp.ownership import check_output

    p = Path(path)
    where = f"{prefix}.run-dir {p.parent} {prefix}.run-name {p.name}" if kind == "run" else f"{prefix}.run-dir {p}"
    if p.is_dir() and any(p.iterdir()):
        if not is_run_dir(p, kind):
            raise InputError(where, f"{p} exists and is not a run directory written by eosp: refusing to write into "
                                    "it (choose another run name)")
        if not (resume or overwrite):
            raise InputError(where, f"{p} already exists: pass {prefix}.resume true to continue it, "
                                    f"{prefix}.overwrite true to replace it, or another run name")
        return p
    try:
        return check_output(p, kind, directory=True, reuse=True)  # not there, or empty: its parent is checked
    except InputError as exc:
        raise InputError(where, f"{p} {exc.message}") from None


def make_run_dir(run_dir: Path, replace: bool, kind: str = "run") -> None:
    """Create the run directory with eosp's mark (eosp.ownership), an old one of eosp's removed first when
    `replace` (--train.overwrite; require_run_dir refused anything else before any service started)."""
    import shutil

    from eosp.ownership import kind_of, mark_dir

    if replace and run_dir.is_dir() and is_run_dir(run_dir, kind):
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if kind_of(run_dir) != kind:
        mark_dir(run_dir, kind)


def require_checkpoint(checkpoint: str, flag: str = "--checkpoint") -> None:
    """A one-line InputError, before any service starts, unless `checkpoint` is empty (the shipped model), a
    shipped model by name (``pretrained:NAME``) or an agent checkpoint that loads (:func:`load_agent`)."""
    from eosp.errors import InputError
    from eosp.models.pretrained import PREFIX, pretrained_dir

    if not checkpoint:
        return
    if checkpoint.startswith(PREFIX):
        pretrained_dir(checkpoint[len(PREFIX):])
        return
    if not Path(checkpoint).exists():
        raise InputError(f"{flag} {checkpoint}", "checkpoint not found")
    from eosp.models.checkpoint import load_agent

    load_agent(checkpoint)
