"""``run_rows``: the row kernels' threads (observe, regularize, fill holes)."""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest

from dmtrack.odometry import _depth_common
from dmtrack.odometry._depth_common import run_rows


def _fill(first: int, step: int, out: np.ndarray, who: list) -> None:
    who.append((first, step, threading.get_ident()))
    for y in range(first, out.shape[0], step):
        out[y] = y * 10 + np.arange(out.shape[1])


@pytest.mark.parametrize("threads", [1, 2])
def test_every_row_once_and_the_same_result_for_any_thread_count(threads: int) -> None:
    if threads > numba.config.NUMBA_NUM_THREADS:
        pytest.skip(f"numba has {numba.config.NUMBA_NUM_THREADS} thread(s)")
    serial, who_serial = np.zeros((37, 5)), []
    run_rows(_fill, (serial, who_serial), parallel=False)
    assert who_serial == [(0, 1, threading.get_ident())]
    prev = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        out, who = np.zeros((37, 5)), []
        run_rows(_fill, (out, who), parallel=True)
    finally:
        numba.set_num_threads(prev)
    assert out.tobytes() == serial.tobytes()
    assert sorted((f, s) for f, s, _ in who) == [(t, threads) for t in range(threads)]
    assert any(ident == threading.get_ident() for f, _, ident in who if f == 0)  # set 0 on the calling thread
    if threads > 1:
        assert len({ident for _, _, ident in who}) == threads


def _fail_on_second(first: int, step: int, done: list) -> None:
    if first == 1:
        raise ValueError("row set 1 failed")
    done.append(first)


def test_an_error_in_a_pool_thread_is_raised_after_all_threads_finished() -> None:
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    prev = numba.get_num_threads()
    numba.set_num_threads(2)
    try:
        done: list = []
        with pytest.raises(ValueError, match="row set 1 failed"):
            run_rows(_fail_on_second, (done,), parallel=True)
        assert done == [0]
    finally:
        numba.set_num_threads(prev)


def test_one_pool_per_process_and_a_new_one_after_a_fork(monkeypatch) -> None:
    pool = _depth_common._row_pool()
    assert _depth_common._row_pool() is pool  # never replaced in a process (no submit to a shut-down pool)
    monkeypatch.setattr(_depth_common.os, "getpid", lambda: -1)  # as in a child after fork
    child = _depth_common._row_pool()
    assert child is not pool
    assert child.submit(sum, (1, 2)).result(timeout=60) == 3
