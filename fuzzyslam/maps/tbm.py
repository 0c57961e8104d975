"""Smets' transferable belief model on the frame {E, O}, vectorised over cells.

A mass function on Omega = {E, O} has four focal sets: E, O, Theta = {E, O} ("don't
know") and the empty set (conflict). Here it is a tuple of arrays ``(m_e, m_o, m_t, m_c)``
of any common shape, summing to 1 cell by cell.

References:
    P. Smets, "The combination of evidence in the transferable belief model", IEEE PAMI
    12(5), 1990 (unnormalised conjunctive rule, commonality functions).
    P. Smets, R. Kennes, "The transferable belief model", Artificial Intelligence 66, 1994
    (discounting, pignistic transformation).
    G. Shafer, "A mathematical theory of evidence", 1976, ch. 11 (discounting).
"""

from __future__ import annotations

import numpy as np

Masses = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def conjunctive(m1: Masses, m2: Masses) -> Masses:
    """Smets' unnormalised conjunctive combination m1 (conj) m2.

    m(A) = sum over B, C with B cap C = A of m1(B) m2(C), on {E, O}::

        m(E)   = m1E m2E + m1E m2T + m1T m2E
        m(O)   = m1O m2O + m1O m2T + m1T m2O
        m(T)   = m1T m2T
        m(emp) = m1C + m2C - m1C m2C + m1E m2O + m1O m2E

    The last term pair is the new contradiction between the two bodies of evidence
    (Smets 1990, eq. 2.2). Commutative and associative; the vacuous function
    (m(T) = 1) is its neutral element.

    Parameters
    ----------
    m1, m2 : tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).

    Returns
    -------
    tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset) of the combination.
    """
    e1, o1, t1, c1 = m1
    e2, o2, t2, c2 = m2
    m_e = e1 * e2 + e1 * t2 + t1 * e2
    m_o = o1 * o2 + o1 * t2 + t1 * o2
    m_t = t1 * t2
    m_c = c1 + c2 - c1 * c2 + e1 * o2 + o1 * e2
    return m_e, m_o, m_t, m_c


def discount(m: Masses, alpha: np.ndarray | float) -> Masses:
    """Discounting with reliability ``alpha`` in [0, 1] (Shafer 1976; Smets & Kennes 1994).

    m'(A) = alpha m(A) for every A != Theta (the empty set included),
    m'(Theta) = 1 - alpha + alpha m(Theta).
    alpha = 1 keeps m; alpha = 0 gives the vacuous function.

    Parameters
    ----------
    m : tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).
    alpha : ndarray, shape (...), or float
        The reliability in [0, 1].

    Returns
    -------
    tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).
    """
    e, o, t, c = m
    return alpha * e, alpha * o, 1.0 - alpha + alpha * t, alpha * c


def forgetting_factor(conflict: np.ndarray, gamma: float) -> np.ndarray:
    """alpha = 1 - gamma * m(emptyset) (docs/models.md sec. 6, following the paper's sec. 3).

    A cell whose stored evidence is contradicted (large conflict mass, e.g. because the
    poses that placed it were wrong) keeps only a fraction of it before the next
    combination, so later, better-placed readings overwrite it.

    Parameters
    ----------
    conflict : ndarray, shape (...)
        m(emptyset) per cell.
    gamma : float
        The forgetting rate.

    Returns
    -------
    ndarray, shape (...)
        alpha.
    """
    return 1.0 - gamma * np.clip(conflict, 0.0, 1.0)


def commonality(m: Masses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Commonalities q(A) = sum of m(B) over B containing A (Smets 1990, sec. 3).

    q(E) = m(E) + m(T), q(O) = m(O) + m(T), q(T) = m(T); q(emptyset) = 1 always.

    Parameters
    ----------
    m : tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).

    Returns
    -------
    q_e, q_o, q_t : ndarray, shape (...)
        q(E), q(O), q(Theta).
    """
    e, o, t, _c = m
    return e + t, o + t, t


def from_commonality(q_e: np.ndarray, q_o: np.ndarray, q_t: np.ndarray) -> Masses:
    """Masses of commonalities (Moebius inversion): m(T) = q(T), m(E) = q(E) - q(T),
    m(O) = q(O) - q(T), m(emptyset) = 1 - q(E) - q(O) + q(T).

    Parameters
    ----------
    q_e, q_o, q_t : ndarray, shape (...)
        q(E), q(O), q(Theta).

    Returns
    -------
    tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).
    """
    return q_e - q_t, q_o - q_t, q_t, 1.0 - q_e - q_o + q_t


def conjunctive_grouped(m: Masses, groups: np.ndarray, ngroups: int) -> Masses:
    """Conjunctive combination of every mass function that shares a group index.

    The conjunctive rule multiplies commonalities, q12(A) = q1(A) q2(A) (Smets 1990,
    eq. 3.3), so the combination of n functions per group is a product, computed as an
    exponentiated sum of logarithms with ``np.bincount`` (no loop over cells). Equivalent
    to folding :func:`conjunctive` over each group in any order (commutativity and
    associativity). Commonalities of zero are handled by counting them separately (only
    when there is one: readings' simple support functions rarely have one).

    Parameters
    ----------
    m : tuple of 4 ndarray, shape (N,)
        The mass functions, m(E), m(O), m(Theta), m(emptyset).
    groups : ndarray of int, shape (N,)
        Each function's group in [0, ngroups).
    ngroups : int
        Number of groups.

    Returns
    -------
    tuple of 4 ndarray, shape (ngroups,)
        The combination per group (vacuous for an empty group).
    """
    q = np.array(commonality(m), dtype=float)  # (3, N): q(E), q(O), q(Theta)
    zero = q <= 0.0
    some_zero = bool(zero.any())
    logq = np.log(np.where(zero, 1.0, q) if some_zero else q)
    # the three commonalities' sums as one bincount over 3 ngroups bins (row k's group g
    # in bin k ngroups + g: each bin adds the same terms in the same order as its own)
    bins = (np.asarray(groups).reshape(1, -1) + ngroups * np.arange(3)[:, None]).ravel()
    s = np.bincount(bins, weights=logq.ravel(), minlength=3 * ngroups).reshape(3, ngroups)
    out = np.exp(s)
    if some_zero:
        nz = np.bincount(bins, weights=zero.ravel().astype(float), minlength=3 * ngroups)
        out = np.where(nz.reshape(3, ngroups) > 0, 0.0, out)
    return from_commonality(out[0], out[1], out[2])


def clip_masses(m: Masses) -> Masses:
    """Remove float rounding: clip to [0, 1] and put the residue on the conflict mass so the
    four masses sum to exactly 1 (up to float precision).

    Parameters
    ----------
    m : tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset).

    Returns
    -------
    tuple of 4 ndarray, each of one shape (...)
        m(E), m(O), m(Theta), m(emptyset), summing to 1.
    """
    e, o, t, _c = (np.clip(x, 0.0, 1.0) for x in m)
    c = np.clip(1.0 - e - o - t, 0.0, 1.0)
    return e, o, t, c
