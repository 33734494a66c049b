"""The work runs without the GIL: threads run concurrently and get the same answers."""

import threading
import time

import numpy as np

import conic_corners as cc
import render as R


def grid_of_corners(n=6, cell=64):
    """n×n X-corners, each in its own cell, and their true positions."""
    rng = np.random.default_rng(3)
    img = np.zeros((n * cell, n * cell))
    truth = []
    for i in range(n):
        for j in range(n):
            c = (cell / 2 - 0.5 + rng.uniform(-0.5, 0.5), cell / 2 - 0.5 + rng.uniform(-0.5, 0.5))
            a = rng.uniform(0, 60)
            img[i * cell:(i + 1) * cell, j * cell:(j + 1) * cell] = R.x_corner(
                size=(cell, cell), centre=c, angles_deg=(a, a + 85), blur=1.0, s=4)
            truth.append((j * cell + c[0], i * cell + c[1]))
    return R.to_u8(img), np.array(truth)


def test_two_threads_refine_concurrently():
    img, truth = grid_of_corners()
    starts = np.round(truth)
    expected, status = cc.refine(img, starts)
    assert (status == cc.CONVERGED).all()
    assert np.abs(expected - truth).max() < 0.05

    results = [None, None]

    def work(k):
        for _ in range(5):
            p, s = cc.refine(img, starts)
            if not (np.array_equal(p, expected) and np.array_equal(s, status)):
                results[k] = "mismatch"
                return
        results[k] = "ok"

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert results == ["ok", "ok"]


def test_gil_is_released_during_refine():
    img, truth = grid_of_corners()
    starts = np.repeat(np.round(truth), 40, axis=0)  # enough work for most of a second
    t0 = time.perf_counter()
    cc.refine(img, starts)
    duration = time.perf_counter() - t0

    done = threading.Event()

    def work():
        cc.refine(img, starts)
        done.set()

    worker = threading.Thread(target=work)
    last, longest = time.perf_counter(), 0.0
    worker.start()
    while not done.is_set():
        now = time.perf_counter()
        longest, last = max(longest, now - last), now
        time.sleep(0.001)  # leave the cores to the refiner's threads
    worker.join()
    # Holding the GIL for the whole call would stall this loop for about `duration`.
    assert longest < 0.5 * duration, (longest, duration)
