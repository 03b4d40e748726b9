"""Checks every job makes before any work: where its outputs go, and whether MLflow answers.

* A job submitted with ``ray job submit --working-dir .`` runs in Ray's temporary,
  unpacked copy of the working dir (``.../runtime_resources/working_dir_files/...``
  under the Ray session directory), which is deleted with the session.  A relative
  run or output directory would land there, where nobody finds it: such a job
  refuses it with one line naming the absolute path to pass.
* An MLflow tracking server that does not answer is reported in one line at the
  start, not after an hour of training.
"""

from __future__ import annotations

import os
import urllib.error
import urllib.request
from pathlib import Path

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
    """SystemExit (one line) when `path` is relative and the job runs from an uploaded working dir."""
    root = uploaded_working_dir()
    if root is None or Path(path).is_absolute():
        return
    raise SystemExit(f"error: {flag} {path!r} is relative, and this job runs in Ray's temporary copy of the "
                     f"working dir ({root}), deleted with the session: pass an absolute path, e.g. "
                     f"{flag} {example.rstrip('/')}/{Path(path).as_posix()}")


def check_mlflow(uri: str, flag: str = "--mlflow-uri", timeout: float = 5.0) -> None:
    """SystemExit (one line) when the tracking URI cannot be used: an HTTP server that does not answer,
    or (from an uploaded working dir) the default database inside Ray's temporary copy."""
    if not uri:
        if uploaded_working_dir() is not None:
            raise SystemExit(f"error: no {flag} given, and the default mlflow.db would be written in Ray's temporary "
                             "copy of the working dir: pass a tracking server (http://...) or "
                             f"{flag} sqlite:////shared/mlflow.db")
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
        raise SystemExit(f"error: MLflow tracking server {uri} unreachable ({reason}): start it, or pass another "
                         f"{flag} (e.g. sqlite:///$PWD/mlflow.db)") from None
