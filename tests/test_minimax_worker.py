"""`design_move` at a given move time solves the minimax LP in a worker thread beside the other candidates
(`jaxbelt.shaping.minimax_solve.solving`). The table must be the one the same call makes with the LP solved in line,
an error in either thread must reach the caller, and no LP may outlive the call."""

import concurrent.futures
import time

import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt.shaping import minimax_solve as ms
from jaxbelt.shaping import moves, plan, shaped, worker

pytestmark = pytest.mark.slow  # a first design_move compiles its programs (~10 s)

AXIS = ([6.0], [0.02])
KW = dict(v_max=0.3, a_max=1.2, uncertainty=0.2)


class _InLine:
    """An executor that runs its work at `submit`, in the caller's thread: the LP solved in line."""

    def submit(self, fn, *args, **kwargs):
        fut: concurrent.futures.Future = concurrent.futures.Future()
        fut.set_result(fn(*args, **kwargs))
        return fut


def _forget():
    """Empty the caches of the last shaped moves and sampled derivatives, so that a second call computes them anew."""
    shaped._RECENT.clear()
    moves._MEMO.clear()


def _table(p):
    return [(r.name, r.worst_percent, r.move_time, r.ok) for r in p.table]


def test_the_worker_makes_the_table_of_the_lp_solved_in_line(monkeypatch):
    """Every row (name, worst residual, move time, status) and the recommendation equal those of the same call with
    the LP solved in the caller's thread: the worker changes when the LP runs, not what it computes (the same
    programs on the same inputs: equal to the last bit)."""
    ax = jb.ModalAxis(*AXIS)
    threaded = jb.design_move(ax, 0.1, 1.0, **KW)
    monkeypatch.setattr(worker, "_WORKER", _InLine())
    _forget()
    in_line = jb.design_move(ax, 0.1, 1.0, **KW)
    assert _table(threaded) == _table(in_line)
    assert threaded.best.name == in_line.best.name
    np.testing.assert_array_equal(np.asarray(threaded.minimax.lp.x), np.asarray(in_line.minimax.lp.x))


def _recording_submit(monkeypatch):
    """Record the futures the worker is given."""
    futures = []
    submit = worker._WORKER.submit

    def record(*args, **kwargs):
        fut = submit(*args, **kwargs)
        futures.append(fut)
        return fut

    monkeypatch.setattr(worker._WORKER, "submit", record)
    return futures


def test_an_error_in_the_worker_reaches_the_caller(monkeypatch):
    """A failure of the LP in the worker is raised by `design_move` itself, with its own type and message."""

    def failing(*args, **kwargs):
        raise RuntimeError("the LP failed here")

    futures = _recording_submit(monkeypatch)
    monkeypatch.setattr(ms, "solve", failing)
    with pytest.raises(RuntimeError, match="the LP failed here"):
        jb.design_move(jb.ModalAxis(*AXIS), 0.1, 1.0, **KW)
    # the LP's preparation (queued by validate), the LP, then the minimax rows that wait for it
    assert len(futures) == 3 and all(f.done() for f in futures)


def test_an_error_beside_the_worker_waits_for_it(monkeypatch):
    """When the caller's thread fails while the LP runs, the error is raised after the LP has finished (or was
    cancelled), and the minimax rows queued after it too: no LP runs on after `design_move` has returned."""
    futures = _recording_submit(monkeypatch)

    measure_rows, calls = plan.measure_rows, []

    def failing(req, built):  # the classic rows (before the LP starts) measured; the timed ones fail
        calls.append(len(built))
        if len(calls) > 1:
            raise ValueError("a candidate failed here")
        return measure_rows(req, built)

    monkeypatch.setattr(plan, "measure_rows", failing)
    with pytest.raises(ValueError, match="a candidate failed here"):
        jb.design_move(jb.ModalAxis(*AXIS), 0.1, 1.0, **KW)
    # the LP's preparation, the LP and the minimax rows: finished or cancelled
    assert len(futures) == 3 and all(f.done() for f in futures)


def test_no_worker_without_a_move_time_or_the_minimax_row(monkeypatch):
    """A table without the minimax row and the shortest-time search (move_time None: the LP's time is what the
    other candidates wait for) start no worker."""
    futures = _recording_submit(monkeypatch)
    p = jb.design_move(jb.ModalAxis(*AXIS), 0.1, 1.0, include=("ZV", "unshaped"), **KW)
    assert futures == [] and {r.name for r in p.table} == {"ZV", "unshaped"}
    p = jb.design_move(jb.ModalAxis(*AXIS), 0.1, None, include=("minimax", "ZV"), **KW)
    assert futures == [] and p.minimax is not None


def test_the_worker_runs_under_the_callers_x64_block():
    """With JAX's 64-bit mode off for the process and on in the caller's `with jax.enable_x64(True):` block (a
    thread-local setting), the LP in the worker runs in 64 bits too: the design equals the one made with the mode on
    for the process (before the worker re-entered the caller's settings, its checks refused the float32 inputs)."""
    import jax

    ax = jb.ModalAxis(*AXIS)
    reference = jb.design_move(ax, 0.1, 1.0, **KW)
    prev = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    _forget()
    try:
        with jax.enable_x64(True):
            in_block = jb.design_move(ax, 0.1, 1.0, **KW)
    finally:
        jax.config.update("jax_enable_x64", prev)
    assert _table(in_block) == _table(reference)
    assert np.asarray(in_block.minimax.lp.x).dtype == np.float64


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="os.fork: POSIX only")
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # the child runs no JAX
def test_a_forked_child_has_a_worker_of_its_own():
    """A child forked after the worker ran (a multiprocessing pool's default start on Linux) gets a worker that
    runs its work: the parent's executor, copied, would never run it (`design_move` would wait forever)."""
    import os
    import time

    worker._WORKER.submit(int).result(timeout=30)  # the parent's worker thread has started
    pid = os.fork()
    if pid == 0:  # the child: no JAX here, only the executor
        try:
            ok = worker._WORKER.submit(int, 7).result(timeout=10) == 7
        except BaseException:  # noqa: BLE001 - any failure is the child's exit status
            ok = False
        os._exit(0 if ok else 1)
    deadline = time.monotonic() + 30
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            pytest.fail("the forked child's worker never ran its work")
        time.sleep(0.05)
    assert os.waitstatus_to_exitcode(status) == 0


def test_the_minimax_rows_queued_after_a_slow_lp_are_made(monkeypatch):
    """The minimax rows queue on the worker after the LP (`minimax_solve.solving`'s `beside`): when the other
    candidates finish first (here: an LP slowed by 2 s), the rows are still made, not cancelled, and equal those of
    the LP solved in line."""
    ax = jb.ModalAxis(*AXIS)
    solve = ms.solve

    def slow(*args, **kwargs):
        time.sleep(2.0)
        return solve(*args, **kwargs)

    monkeypatch.setattr(ms, "solve", slow)
    threaded = jb.design_move(ax, 0.1, 1.0, **KW)
    monkeypatch.setattr(worker, "_WORKER", _InLine())
    _forget()
    in_line = jb.design_move(ax, 0.1, 1.0, **KW)
    assert _table(threaded) == _table(in_line) and "minimax" in {r.name for r in threaded.table}
