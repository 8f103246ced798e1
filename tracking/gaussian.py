"""Batched Gaussian arithmetic over stacks of small symmetric positive-definite matrices.

Filters and fusion spend their time inverting many 2x2 and 4x4 covariances at once. Generic
``np.linalg.inv`` on a stack of tiny matrices pays per-matrix overhead, so the common sizes use
closed forms over the whole stack (2x2 adjugate; 4x4 by 2x2 blocks and the Schur complement).
"""

from __future__ import annotations

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))

try:
    from numpy.linalg import _umath_linalg as _lapack
except ImportError:  # pragma: no cover
    _lapack = None

try:
    from numpy._core.multiarray import c_einsum
except ImportError:  # pragma: no cover (NumPy 1.x)
    c_einsum = np.einsum
"""``np.einsum`` without its Python wrapper: what ``np.einsum(..., optimize=False)`` (the
default) calls, so the same numbers; the wrapper costs more than a small stack's product."""


def _inv_det_2x2(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray):
    """Elementwise inverse entries and determinant of [[a, b], [c, d]]."""
    det = a * d - b * c
    r = 1.0 / det
    return d * r, -b * r, -c * r, a * r, det


def inv_det_2x2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of a stack ``S (..., 2, 2)``."""
    ia, ib, ic, id_, det = _inv_det_2x2(S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1])
    inv = np.empty_like(S)
    inv[..., 0, 0] = ia
    inv[..., 0, 1] = ib
    inv[..., 1, 0] = ic
    inv[..., 1, 1] = id_
    return inv, det


def sym4_inverse_entries(a00, a01, a02, a03, a11, a12, a13, a22, a23, a33):
    """Inverse and determinant of symmetric 4x4 matrices given as their 10 upper entries.

    Each argument is an array (any shape, broadcast together). Blocks ``[[A, B], [B^T, D]]`` of
    size 2: ``S = D - B^T A^-1 B`` (Schur complement), ``det = det A det S``, block inverse
    (:func:`sym4_inverse_into`). Returns ``(i00, i01, i02, i03, i11, i12, i13, i22, i23, i33),
    det``.
    """
    args = (a00, a01, a02, a03, a11, a12, a13, a22, a23, a33)
    shape = np.broadcast_shapes(*(np.shape(a) for a in args))
    dtype = np.result_type(*args, 1.0)
    A = np.empty((10, *(shape or (1,))), dtype)
    for k, a in enumerate(args):
        A[k] = a
    P, det = _sym4_inverse(A)
    if not shape:  # scalars in, scalars out
        return tuple(P[i, j, 0] for i, j in SYM4_INDEX), det[0]
    return tuple(P[i, j] for i, j in SYM4_INDEX), det


def _sym4_inverse(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sym4_inverse_into` with new output and scratch arrays."""
    P = np.empty((4, 4, *A.shape[1:]), A.dtype)
    det = np.empty(A.shape[1:], A.dtype)
    sym4_inverse_into(A, P, det, np.empty((SYM4_WORK, *A.shape[1:]), A.dtype))
    return P, det


SYM4_WORK = 23
"""Scratch planes :func:`sym4_inverse_into` needs."""


def _sym2_inverse_into(a, b, d, inv, det, recip, t1, t2) -> None:
    """``[[a, b], [b, d]]^-1 = [[d, -b], [-b, a]] / det`` into ``inv (2, 2, ...)``, with its
    determinant into ``det`` and ``1 / det`` into ``recip``; ``t1``, ``t2`` are scratch."""
    np.multiply(a, d, out=t1)
    np.multiply(b, b, out=t2)
    np.subtract(t1, t2, out=det)
    np.divide(1.0, det, out=recip)
    np.multiply(d, recip, out=inv[0, 0])
    np.negative(b, out=t1)
    np.multiply(t1, recip, out=inv[0, 1])
    np.multiply(a, recip, out=inv[1, 1])
    inv[1, 0] = inv[0, 1]


def sym4_inverse_into(A: np.ndarray, P: np.ndarray, det: np.ndarray, work: np.ndarray) -> None:
    """The closed-form inverse of :func:`sym4_inverse_entries`, written into given arrays.

    ``A (10, ...)``: the upper entries in :data:`SYM4_INDEX` order (read only). Fills the full
    inverse ``P (4, 4, ...)`` (exactly symmetric) and ``det (...)``; ``work (SYM4_WORK, ...)``
    is scratch. The same shape ``...`` (at least one axis) after the first axes; several
    entries per NumPy call, no temporaries. With ``A^-1 = [[a11, -a01], [-a01, a00]] / det A``,
    ``X = A^-1 B``, ``S = D - B^T X``: ``P = [[A^-1 - U X^T, U], [U^T, S^-1]]``,
    ``U = -X S^-1``, and ``det = det A det S``.
    """
    mul, add, sub, neg = np.multiply, np.add, np.subtract, np.negative
    a00, a01, a02, a03, a11, a12, a13, _, _, a33 = A
    Ai, X, T, T2 = (work[k:k + 4].reshape(2, 2, *work.shape[1:]) for k in (0, 4, 8, 12))
    t1, t2, det_a, r_a, s11, det_s, r_s = work[16:23]
    _sym2_inverse_into(a00, a01, a11, Ai, det_a, r_a, t1, t2)
    # X = A^-1 B: x_rc = Ai_r0 a_0(2+c) + Ai_r1 a_1(2+c)
    mul(Ai[:, 0, None], A[None, 2:4], out=X)
    mul(Ai[:, 1, None], A[None, 5:7], out=T)
    add(X, T, out=X)
    # S: [s00, s01] = [a22, a23] - (a02 [x00, x01] + a12 [x10, x11]); s11 likewise
    s0 = T2[0]
    mul(a02, X[0], out=T[0])
    mul(a12, X[1], out=T[1])
    add(T[0], T[1], out=T[0])
    sub(A[7:9], T[0], out=s0)
    s00, s01 = s0
    mul(a03, X[0, 1], out=t1)
    mul(a13, X[1, 1], out=t2)
    add(t1, t2, out=t1)
    sub(a33, t1, out=s11)
    _sym2_inverse_into(s00, s01, s11, P[2:4, 2:4], det_s, r_s, t1, t2)  # S^-1
    # U = -X S^-1: u_rc = -(x_r0 t_0c + x_r1 t_1c)
    U = P[0:2, 2:4]
    mul(X[:, 0, None], P[None, 2, 2:4], out=U)
    mul(X[:, 1, None], P[None, 3, 2:4], out=T)
    add(U, T, out=U)
    neg(U, out=U)
    # A^-1 - U X^T: e_rc = Ai_rc - (u_r0 x_c0 + u_r1 x_c1), then e10 := e01
    mul(U[:, 0, None], X[None, :, 0], out=T)
    mul(U[:, 1, None], X[None, :, 1], out=T2)
    add(T, T2, out=T)
    sub(Ai, T, out=P[0:2, 0:2])
    P[1, 0] = P[0, 1]
    P[2:4, 0:2] = U.swapaxes(0, 1)
    mul(det_a, det_s, out=det)


SYM4_INDEX = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))
"""The 10 upper-triangle positions of a 4x4 matrix, in the order used above."""


def sym4_assemble(entries, shape: tuple[int, ...]) -> np.ndarray:
    """Build ``(*shape, 4, 4)`` symmetric matrices from their 10 upper entries.

    The result is a (non-contiguous) view of one ``(16, n)`` block: no per-entry scatter.
    """
    n = int(np.prod(shape))
    e00, e01, e02, e03, e11, e12, e13, e22, e23, e33 = (
        np.broadcast_to(e, shape).reshape(n) for e in entries
    )
    flat = np.stack((e00, e01, e02, e03, e01, e11, e12, e13, e02, e12, e22, e23, e03, e13, e23,
                     e33))
    return flat.T.reshape(*shape, 4, 4)


def inv_det_sym4(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of a stack of symmetric 4x4 matrices ``C (..., 4, 4)``."""
    shape = C.shape[:-2]
    A = np.empty((10, *(shape or (1,))), np.result_type(C, 1.0))
    for k, (i, j) in enumerate(SYM4_INDEX):
        A[k] = C[..., i, j]
    P, det = _sym4_inverse(A)
    if not shape:  # one matrix
        return P[:, :, 0], det[0]
    return np.moveaxis(P, (0, 1), (-2, -1)), det


def inv_det_spd(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of a stack of SPD matrices ``P (..., d, d)``, any ``d``.
    LAPACK's ufuncs are called without ``np.linalg``'s Python wrappers (the same calls, so the
    same numbers; the wrappers cost more than inverting ten 4x4 matrices); a singular or
    non-finite stack goes through ``np.linalg`` and its errors."""
    if _generic_inverse(P):
        if _lapack is not None and P.dtype == np.float64:
            with np.errstate(all="ignore"):
                inv = _lapack.inv(P, signature="d->d")
                det = _lapack.det(P, signature="d->d")
            if _all(np.isfinite(inv), axis=None):
                return 0.5 * (inv + inv.swapaxes(-1, -2)), det
        return inv_spd(P), np.linalg.det(P)
    d = P.shape[-1]
    if d == 2:
        return inv_det_2x2(P)
    if d == 4:
        return inv_det_sym4(P)
    return 1.0 / P, P[..., 0, 0]


def inv_spd(P: np.ndarray) -> np.ndarray:
    """The inverse part of :func:`inv_det_spd` (the same numbers), without the determinant."""
    if _generic_inverse(P):
        inv = _lapack_inv(P) if P.dtype == np.float64 else None
        if inv is None:  # singular, non-finite or not float64: np.linalg.inv and its errors
            inv = np.linalg.inv(P)
        return 0.5 * (inv + inv.swapaxes(-1, -2))
    return inv_det_spd(P)[0]


_all = np.logical_and.reduce


def _lapack_inv(P: np.ndarray) -> np.ndarray | None:
    """``np.linalg.inv(P)`` (the same LAPACK call, so the same numbers) without its Python
    wrapper, which costs more than inverting a few 4x4 matrices; None where a matrix is
    singular or the result is not finite."""
    if _lapack is None:  # pragma: no cover (NumPy without the private module)
        return None
    with np.errstate(all="ignore"):
        inv = _lapack.inv(P, signature="d->d")
    return inv if _all(np.isfinite(inv), axis=None) else None  # .all() without its wrapper


def _generic_inverse(P: np.ndarray) -> bool:
    """Whether :func:`inv_det_spd` uses LAPACK (else a closed form: 1x1, 2x2, large 4x4 stacks)."""
    d = P.shape[-1]
    return d not in (1, 2) and not (d == 4 and (P.ndim > 3 or P.shape[0] > 200))


def quad_form(diff: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """``diff^T inv diff`` over stacks: diff (..., d), inv (..., d, d) -> (...)."""
    return np.einsum("...i,...ij,...j->...", diff, inv, diff)


def log_gaussian(diff: np.ndarray, inv: np.ndarray, det: np.ndarray) -> np.ndarray:
    """``log N(diff; 0, P)`` given ``P^-1`` and ``det P`` (broadcast over leading axes)."""
    d = diff.shape[-1]
    return -0.5 * (quad_form(diff, inv) + np.log(det) + d * LOG_2PI)


def gaussian_pdf_points(x: np.ndarray, means: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """``N(x_p; m_j, P_j)`` for points ``x (p, d)`` and components ``(n, d)``: ``(p, n)``."""
    inv, det = inv_det_spd(covs)
    diff = x[:, None, :] - means[None, :, :]
    return np.exp(log_gaussian(diff, inv[None], det[None]))


def symmetrise(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` over a stack: removes round-off asymmetry."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))
