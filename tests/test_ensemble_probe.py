"""benchmarks/ensemble_probe.py: combining generators' sample sets without retraining."""

import numpy as np
from bench import load_benchmark


def test_matching_undoes_a_permutation_and_averaging_two_copies_changes_nothing():
    probe = load_benchmark("ensemble_probe")
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 3, 4, 2))  # [K, N, T_f, 2]
    shuffled = a[[3, 0, 4, 1, 2]]  # the same samples in another order
    np.testing.assert_allclose(probe.matched_mean([a, shuffled]), a)
    # two sets that differ by a constant offset average to the midway set
    np.testing.assert_allclose(probe.matched_mean([a, a + 1.0]), a + 0.5)


def test_respread_restores_the_singles_spread_about_the_centroid():
    probe = load_benchmark("ensemble_probe")
    rng = np.random.default_rng(1)
    a = rng.normal(size=(6, 2, 4, 2))
    shrunk = a.mean(0, keepdims=True) + 0.5 * (a - a.mean(0, keepdims=True))
    back = probe.respread(shrunk, [a, a])
    np.testing.assert_allclose(back, a, atol=1e-9)


def test_min_errors_by_hand():
    probe = load_benchmark("ensemble_probe")
    future = np.zeros((1, 2, 2))  # one agent, two steps, at the origin
    pred = np.stack([np.full((1, 2, 2), 3.0), np.array([[[0.0, 1.0], [0.0, 2.0]]])])  # [2, 1, 2, 2]
    m = probe.min_errors(pred, future)
    assert np.isclose(m["min_ade"], 1.5) and np.isclose(m["min_fde"], 2.0)


def test_union_medoids_keeps_k_of_the_union():
    probe = load_benchmark("ensemble_probe")
    rng = np.random.default_rng(2)
    sets = [rng.normal(size=(4, 3, 2, 2)).astype(np.float32) for _ in range(2)]
    kept = probe.union_medoids(sets, 4)
    assert kept.shape == (4, 3, 2, 2)
    union = np.concatenate(sets, 0)
    for n in range(3):  # every kept sample is one of the union's, unchanged
        for k in range(4):
            assert np.any(np.all(np.isclose(union[:, n], kept[k, n]), axis=(1, 2)))
