import functools
import os
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
# what the tests compile and remember stays out of the repository tree: numba's cache (also for the subprocesses
# the tests start) and hypothesis' example database go to the temp dir, kept between runs so that reruns are warm
_TMP = Path(tempfile.gettempdir()) / f"eosp-tests-{os.getuid()}"
os.environ.setdefault("NUMBA_CACHE_DIR", str(_TMP / "numba-cache"))

from hypothesis import settings  # noqa: E402
from hypothesis.database import DirectoryBasedExampleDatabase  # noqa: E402

settings.register_profile("eosp", database=DirectoryBasedExampleDatabase(str(_TMP / "hypothesis")))
settings.load_profile("eosp")

import pytest  # noqa: E402

from eosp.config import family_config  # noqa: E402


@functools.lru_cache(maxsize=None)
def generated(family: str = "uniform", n: int = 12, seed: int = 0, step: float = 2.0, slew: str = "piecewise"):
    """A small generated instance (cached: tests must not modify it)."""
    from eosp.instances.generator import generate

    return generate(family_config(family, n, seed, graph={"step_s": step}, satellite={"slew_model": slew}))


def clustered_scenario(root: Path, tasks: int = 120, seed: int = 3) -> Path:
    """A 4-hour day of 6 satellites over targets in four clusters (passes with several primaries: gaps and
    replacements to choose among), as a fleet ROOT/fleet and an operations scenario ROOT/scen (4 urgent requests an
    hour, a planning call an hour, scenario seed `seed`); the scenario's path."""
    from eosp.fleet.generate import FleetGenConfig, generate
    from eosp.fleet.geometry import Geometry
    from eosp.fleet.io import write_fleet
    from eosp.fleet.opportunities import compute
    from eosp.ops.scenario import ScenarioConfig, make

    if not (root / "fleet").exists():
        f = generate(FleetGenConfig(satellites=6, tasks=tasks, hours=4.0, placement="clusters", clusters=4,
                                    cluster_km=150.0, seed=6))
        write_fleet(f, compute(f, Geometry(f)), root / "fleet")
    make(str(root / "fleet"), ScenarioConfig(urgent_per_hour=4, cadence_h=1, seed=seed), str(root / "scen"))
    return root / "scen"


@pytest.fixture
def tiny():
    return generated("uniform", 12, 0, 2.0)


# Tests that start Ray (or Ray-based jobs and services) carry the marker `ray`: `make test` runs the others on two
# pytest-xdist workers, then these one after another with the cores to themselves (two Ray clusters, or a Ray
# cluster beside a CPU-bound worker, starve each other and make the timing-sensitive ones flaky).
RAY_MODULES = {"test_platform", "test_platform_multinode", "test_train", "test_tune", "test_jobs_faults",
               "test_jobs_smoke", "test_overlap", "test_expert", "test_readme", "test_fleet_ray",
               "test_train_prices", "test_train_onboard"}
RAY_TESTS = {"test_shard_source_splits_shards_between_workers"}
# The extended suite (marker `extended`, `make test-extended`, run by CI after `make test`): the slowest Ray tests
# (whole services and jobs killed and resumed, multi-node clusters, training variants, the README's blocks, each
# 8-65 s), which `make test` leaves out to stay within 10 minutes on a 2-core machine.  Nothing leaves CI.
EXTENDED_MODULES = {"test_platform", "test_platform_multinode", "test_readme", "test_overlap", "test_jobs_ctrl_c"}
EXTENDED_TESTS = {"test_ppo_starts_from_an_imitation_checkpoint", "test_demonstrations_imitation_with_dagger_ppo_and_a_sweep",
                  "test_evaluate_killed_and_rerun_gives_the_same_report", "test_build_shards_killed_and_rerun_resumes",
                  "test_train_job_refuses_what_the_local_ray_cannot_run", "test_tune_refuses_a_gpu_learner_without_a_gpu",
                  "test_data_training_mlflow_resume_and_refusal", "test_demos_replay_to_the_expert_value_with_allowed_actions",
                  "test_pretrain_continues_a_shipped_model_and_refuses_a_missing_one",
                  "test_pretrain_saves_the_weight_average_and_decays_the_learning_rate"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        module = item.module.__name__.rpartition(".")[2]
        if module in RAY_MODULES or item.originalname in RAY_TESTS:
            item.add_marker(pytest.mark.ray)
        if module in EXTENDED_MODULES or item.originalname in EXTENDED_TESTS:
            item.add_marker(pytest.mark.extended)


@pytest.fixture
def default_sigint():
    """Python's own SIGINT handler for the test, the one before it given back after.  A shell that starts the suite
    in the background (`make test &`, a detached terminal, many CI runners) hands Python an ignored SIGINT, and
    Python then installs no handler: the tests that raise SIGINT in this process and assert what Ctrl-C does to a
    program (a KeyboardInterrupt) set what a foreground terminal gives."""
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def sigint_as_a_terminal_gives() -> None:
    """`preexec_fn` of a child that is sent SIGINT: the default disposition (death, or Python's KeyboardInterrupt),
    not the ignored one a background shell leaves to the test run."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def sigint_to_group(p, wait_s: float = 30.0) -> tuple[int, str, float]:
    """Send SIGINT to the process group of `p` (started with ``start_new_session=True``), as a terminal's Ctrl-C
    does; (exit status, stderr, seconds from the signal until every process of the group is gone, at most
    `wait_s` after the exit); a group still running 60 s after the signal is killed: (-9, stderr, inf)."""
    import os
    import signal
    import subprocess
    import time

    t0 = time.monotonic()
    os.killpg(p.pid, signal.SIGINT)
    try:
        _, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        _, err = p.communicate()
        return -9, err, float("inf")
    while time.monotonic() - t0 < wait_s:  # the workers too
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    return p.returncode, err, time.monotonic() - t0


@pytest.fixture(scope="session")
def chromium():
    """The path of a headless Chromium for the page tests (tests/browser.py finds or installs one); the test is
    skipped, with the reason, where none can be had."""
    from tests.browser import ensure_chromium

    path, why = ensure_chromium()
    if path is None:
        pytest.skip(why)
    return path


_EXIT_STATUS: list[int] = []


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS.append(int(exitstatus))


def pytest_unconfigure(config):
    """Leave at once once pytest has reported (the controller process only, not an xdist worker): the test run's
    status is final, and the interpreter's teardown of native libraries (Ray's and torch's C++ globals) can
    crash after every test passed (one `Segmentation fault`, exit 139, seen after a green Ray phase).  Ray is shut
    down first, so no process of it is left behind."""
    import sys

    if hasattr(config, "workerinput") or not _EXIT_STATUS:
        return
    if "ray" in sys.modules:
        import ray

        if ray.is_initialized():
            ray.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_EXIT_STATUS[-1])
