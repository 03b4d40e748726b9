"""MLflow for the jobs: one tracking URI, and experiments whose artifacts lie next to the store the user named.

MLflow's SQL stores keep run data in the database and the artifacts (schedules, plots, models) elsewhere: by default
in ``./mlruns`` of whatever directory the job happens to run in, far from ``--mlflow-uri sqlite:///DIR/mlflow.db``.
An experiment created here puts them in ``DIR/mlartifacts`` instead (an experiment that exists keeps the location it
was created with).  A tracking server (http://...) chooses its artifact store itself.
"""

from __future__ import annotations

from pathlib import Path

SQLITE = "sqlite:///"
ARTIFACTS = "mlartifacts"


def sqlite_path(uri: str) -> Path | None:
    """The database file of a ``sqlite:///PATH`` URI (``sqlite:////abs`` or ``sqlite:///rel``), else None."""
    return Path(uri[len(SQLITE):]) if uri.startswith(SQLITE) else None


def use_experiment(uri: str, name: str):
    """Point MLflow at `uri` (empty: mlflow.db in the working directory) and at experiment `name`, created with its
    artifacts next to a sqlite store; returns the experiment (``mlflow.set_experiment``'s)."""
    import mlflow
    from mlflow.exceptions import MlflowException

    from eosp.config import default_mlflow_uri

    uri = default_mlflow_uri(uri)
    mlflow.set_tracking_uri(uri)
    db = sqlite_path(uri)
    if db is not None and mlflow.get_experiment_by_name(name) is None:
        try:
            mlflow.create_experiment(name, artifact_location=(db.resolve().parent / ARTIFACTS).as_uri())
        except MlflowException:  # created meanwhile by another process (Tune trials): theirs is as good
            pass
    return mlflow.set_experiment(name)
