"""``omaps.parallel``: every work item taken exactly once, on any number of threads, and the
bakers' states the same on one thread and two."""

import numba
import numpy as np
import pytest

from omaps.alpha_test import StateRule
from omaps.bake.micromap import GROW_TEXEL, bake_micromaps
from omaps.parallel import fetch_add
from omaps.texture import load_alpha


@numba.njit(parallel=True)
def _take_all(n, n_workers, step):
    taken = np.zeros(n, np.int64)
    counter = np.zeros(1, np.int64)
    for w in numba.prange(n_workers):
        while True:
            i = fetch_add(counter, step)
            if i >= n:
                break
            for k in range(i, min(i + step, n)):
                taken[k] += 1
    return taken, counter


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("n, step", [(0, 1), (1, 1), (1000, 1), (1001, 7), (5, 64)])
def test_every_item_taken_once(threads, n, step):
    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        n_workers = numba.get_num_threads()
        taken, counter = _take_all(n, n_workers, step)
        final = int(counter[0])
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(taken, np.ones(n, np.int64))
    # one call per item handed out, and one more per worker, which finds none left
    assert final == step * (-(-n // step) + n_workers)


def test_fetch_add_returns_the_value_before():
    @numba.njit
    def seq():
        c = np.zeros(1, np.int64)
        return fetch_add(c, 3), fetch_add(c, 3), fetch_add(c, -1), c[0]

    assert seq() == (0, 3, 6, 5)


def test_fetch_add_rejects_other_arrays():
    @numba.njit
    def bad(a):
        return fetch_add(a, 1)

    with pytest.raises(numba.core.errors.TypingError):
        bad(np.zeros(1, np.float64))


def test_bake_same_on_one_thread_and_two():
    rng = np.random.default_rng(3)
    alpha = (rng.random((40, 40)) * 255).astype(np.uint8)
    grid = StateRule("cutoff").alpha_test(load_alpha(alpha), "linear", "wrap").grid()
    centres = rng.random((3000, 1, 2))
    tris = centres + rng.normal(0, 0.05, (3000, 3, 2))
    before = numba.get_num_threads()
    out = []
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            out.append(bake_micromaps(grid, tris, 3, GROW_TEXEL)[0])
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(out[0], out[1])
