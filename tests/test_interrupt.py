"""eosp.interrupt: HeldInterrupt (Ctrl-C recorded inside the block, delivered at its end, never lost) and a program's
Ctrl-C read as such when a library turned it into another error (ProgramInterrupt, through the jobs' run_job)."""

import signal
import threading

import pytest

from eosp.interrupt import HeldInterrupt

pytestmark = pytest.mark.usefixtures("default_sigint")


def test_a_ctrl_c_inside_the_block_waits_for_its_end():
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with HeldInterrupt() as held:
            signal.raise_signal(signal.SIGINT)
            steps.append(held.seen)  # still running: the signal was only recorded
            steps.append("edit finished")
    assert steps == [True, "edit finished"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_block_without_ctrl_c_changes_nothing_and_nested_blocks_deliver_once():
    with HeldInterrupt() as held:
        pass
    assert not held.seen and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        with HeldInterrupt() as outer:
            with HeldInterrupt() as inner:
                signal.raise_signal(signal.SIGINT)
            assert inner.seen and outer.seen  # the inner block delivers to the outer one, still holding it
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_handler_set_by_the_program_runs_at_the_end_and_an_ignored_sigint_stays_ignored():
    calls = []
    previous = signal.signal(signal.SIGINT, lambda *_: calls.append("handler"))
    try:
        with HeldInterrupt():
            signal.raise_signal(signal.SIGINT)
            assert calls == []
        assert calls == ["handler"]
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with HeldInterrupt() as held:
            signal.raise_signal(signal.SIGINT)
        assert not held.seen and signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_outside_the_main_thread_the_block_is_plain():
    seen = []

    def work():
        with HeldInterrupt() as held:
            seen.append(held.seen)

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert seen == [False] and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_interrupt_tests_pass_in_a_run_started_with_sigint_ignored(tmp_path):
    """A run started in the background inherits an ignored SIGINT (Python then installs no handler): one of the tests
    above, in a child pytest started so, passes all the same (the `default_sigint` fixture)."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
                        f"{Path(__file__).name}::test_a_ctrl_c_inside_the_block_waits_for_its_end"],
                       cwd=root / "tests", capture_output=True, text=True, timeout=120,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert r.returncode == 0 and "1 passed" in r.stdout, r.stdout + r.stderr


def test_a_job_reads_ctrl_c_that_a_library_made_another_error_as_ctrl_c(tmp_path, capsys):
    """numba's dispatcher returns SystemError('... returned a result with an exception set') when Ctrl-C lands in a
    compiled call (seen in a fleet PPO job): still the interrupt's one line and exit 130, the MLflow run KILLED,
    Python's handler given back; the same error without Ctrl-C stays a defect with its traceback."""
    import mlflow

    from eosp.args import run_job

    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'mlflow.db'}")
    mlflow.set_experiment("interrupt")  # not the experiment id an earlier test of this worker left active

    def job(argv):
        run = mlflow.start_run(run_name="stopped")
        ids.append(run.info.run_id)
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(<function f>) returned a result with an exception set") from exc
        return 0

    ids: list[str] = []
    assert run_job(job, [], "job.py") == 130
    err = [x for x in capsys.readouterr().err.splitlines() if x.startswith("job.py")]  # not MLflow's own lines
    assert err == ["job.py: interrupted: stopped (files completed before the interrupt are kept)"]
    assert mlflow.get_run(ids[0]).info.status == "KILLED" and mlflow.active_run() is None
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler

    def broken(argv):
        raise SystemError("a defect")

    with pytest.raises(SystemError):
        run_job(broken, [], "job.py")
