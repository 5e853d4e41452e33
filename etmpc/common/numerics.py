"""Sums that decide, computed the same way on every machine.

A BLAS dot product (``a @ b``) adds its terms in an order chosen by the kernel that the CPU selects
(SSE, AVX2, AVX-512), with or without fused multiply-adds, and with as many threads as it likes: the
last bits of the result depend on the machine. Measured with the same numpy and OpenBLAS 0.3.31:
for two terms that overflow to ``+inf`` and ``-inf``, ``OPENBLAS_CORETYPE=Haswell`` gives ``nan``
and ``SkylakeX`` gives ``-inf`` (a fused multiply-add adds the exact product ``1e318`` to ``-inf``);
an LQR correction computed with ``@`` moved every cart-pendulum trajectory in its last bits.

Wherever a sum decides something (a feedback input, an event trigger's decision value, a learned policy's choice),
it is computed here instead: each product is rounded as IEEE-754 multiplication rounds it (the same
everywhere), and the products are added *exactly* and rounded once (:func:`math.fsum`), so the result
does not depend on the order of the terms, on the vector width or on the number of threads.
"""

from __future__ import annotations

import math

import numpy as np

_DOWN, _UP = 2.0**-64, 2.0**64  # exact scalings (powers of two) for sums whose partials overflow


def fsum(terms) -> float:
    """The sum of ``terms`` (floats), exactly rounded once, in any order of the terms.

    ``+inf`` and ``-inf`` among the terms give ``nan``; a ``nan`` term gives ``nan``; finite terms
    whose exact sum lies beyond the double range give ``+inf`` or ``-inf`` by its sign.
    """
    terms = list(terms)
    try:
        return math.fsum(terms)
    except ValueError:  # math.fsum refuses -inf + inf
        return math.nan
    except OverflowError:  # a partial sum of finite terms overflowed: sum them scaled down, then scale back
        return math.fsum(t * _DOWN for t in terms) * _UP


def dot(a, b) -> float:
    """``sum_i a_i b_i`` (1-D), the same on every IEEE-754 machine (see the module's docstring)."""
    return fsum((np.asarray(a, dtype=float) * np.asarray(b, dtype=float)).tolist())


def matvec(matrix, vector) -> np.ndarray:
    """``matrix @ vector``, each row by :func:`dot`."""
    vector = np.asarray(vector, dtype=float)
    return np.array([dot(row, vector) for row in np.atleast_2d(np.asarray(matrix, dtype=float))])


def norm(vector) -> float:
    """The Euclidean norm ``sqrt(v . v)`` (the square root is correctly rounded everywhere)."""
    return math.sqrt(dot(vector, vector))


def cholesky(matrix) -> np.ndarray:
    """The lower-triangular ``L`` with ``L L' = matrix`` (symmetric, positive semidefinite), each entry's sum
    by :func:`fsum`: the same on every machine, unlike LAPACK's. A pivot that is not positive (a semidefinite
    matrix, to rounding) leaves its column 0: ``L L'`` is then the matrix on the rest."""
    a = np.asarray(matrix, dtype=float)
    n = a.shape[0]
    root = np.zeros((n, n))
    for j in range(n):
        pivot = a[j, j] - dot(root[j, :j], root[j, :j])
        if not pivot > 0:
            continue
        root[j, j] = math.sqrt(pivot)
        for i in range(j + 1, n):
            root[i, j] = (a[i, j] - dot(root[i, :j], root[j, :j])) / root[j, j]
    return root
