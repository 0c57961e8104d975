"""Smets' calculus on cell arrays: invariants, algebra, and the FGM update sequence."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.tbm import (
    clip_masses,
    conjunctive,
    conjunctive_grouped,
    discount,
    forgetting_factor,
)


def random_masses(rng: np.random.Generator, n: int):
    """n random mass functions on {E, O, T, emptyset} (Dirichlet)."""
    m = rng.dirichlet(np.ones(4), size=n).T
    return tuple(m)


def test_combination_commutative_and_associative():
    rng = np.random.default_rng(4)
    a, b, c = (random_masses(rng, 500) for _ in range(3))
    ab = conjunctive(a, b)
    ba = conjunctive(b, a)
    np.testing.assert_allclose(np.array(ab), np.array(ba), atol=1e-12)
    left = conjunctive(conjunctive(a, b), c)
    right = conjunctive(a, conjunctive(b, c))
    np.testing.assert_allclose(np.array(left), np.array(right), atol=1e-12)
    np.testing.assert_allclose(np.sum(ab, axis=0), 1.0, atol=1e-12)


def test_vacuous_is_neutral_and_discount_limits():
    rng = np.random.default_rng(5)
    a = random_masses(rng, 100)
    vac = (np.zeros(100), np.zeros(100), np.ones(100), np.zeros(100))
    np.testing.assert_allclose(np.array(conjunctive(a, vac)), np.array(a), atol=1e-12)
    np.testing.assert_allclose(np.array(discount(a, 1.0)), np.array(a), atol=1e-12)
    np.testing.assert_allclose(np.array(discount(a, 0.0)), np.array(vac), atol=1e-12)


def test_conflict_is_the_contradiction():
    """E against O: all the product mass goes to the empty set."""
    e = (np.array([1.0]), np.array([0.0]), np.array([0.0]), np.array([0.0]))
    o = (np.array([0.0]), np.array([1.0]), np.array([0.0]), np.array([0.0]))
    m = conjunctive(e, o)
    assert m[3][0] == 1.0 and m[0][0] == 0.0 and m[1][0] == 0.0
    assert forgetting_factor(m[3], 1.0)[0] == 0.0


def test_grouped_combination_equals_sequential_fold():
    """The commonality-product implementation against folding the mass-form rule."""
    rng = np.random.default_rng(6)
    n, groups = 300, 40
    g = rng.integers(0, groups, n)
    e = rng.uniform(0, 0.5, n)
    o = rng.uniform(0, 0.5, n)
    m = (e, o, 1 - e - o, np.zeros(n))
    got = conjunctive_grouped(m, g, groups)
    for k in range(groups):
        acc = (np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1))
        for i in np.flatnonzero(g == k):
            acc = conjunctive(acc, tuple(x[i : i + 1] for x in m))
        np.testing.assert_allclose([x[k] for x in got], [x[0] for x in acc], atol=1e-12)


updates = st.lists(
    st.tuples(
        st.floats(0.0, 1.0),  # m(E) share
        st.floats(0.0, 1.0),  # m(O) share
        st.floats(0.0, 1.0),  # gamma
    ),
    min_size=1,
    max_size=40,
)


@settings(max_examples=60, deadline=None)
@given(updates)
def test_masses_stay_valid_after_any_update_sequence(seq):
    """Discount-then-combine (the FGM's update) keeps masses in [0, 1], summing to 1."""
    bm = BeliefMap.vacuous(Grid((0.0, 0.0), 0.1, (1, 8)))
    m = tuple(x.ravel().astype(float) for x in (bm.m_e, bm.m_o, bm.m_t, bm.m_c))
    ramp = np.linspace(0.0, 1.0, 8)
    for se, so, gamma in seq:
        e = se * ramp
        o = (1 - e) * so * ramp[::-1]
        ev = (e, o, 1 - e - o, np.zeros(8))
        m = clip_masses(conjunctive(discount(m, forgetting_factor(m[3], gamma)), ev))
        arr = np.array(m)
        assert np.all(arr >= 0.0) and np.all(arr <= 1.0)
        np.testing.assert_allclose(arr.sum(axis=0), 1.0, atol=1e-9)
