"""Batched Gaussian arithmetic over stacks of small symmetric positive-definite matrices.

Filters and fusion spend their time inverting many 2x2 and 4x4 covariances at once. Generic
``np.linalg.inv`` on a stack of tiny matrices pays per-matrix overhead, so the common sizes use
closed forms over the whole stack (2x2 adjugate; 4x4 by 2x2 blocks and the Schur complement).
"""

from __future__ import annotations

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))


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
    size 2: ``S = D - B^T A^-1 B`` (Schur complement), ``det = det A det S``, block inverse.
    Returns ``(i00, i01, i02, i03, i11, i12, i13, i22, i23, i33), det``.
    """
    detA = a00 * a11 - a01 * a01
    rA = 1.0 / detA
    i00, i01, i11 = a11 * rA, -a01 * rA, a00 * rA  # A^-1
    # X = A^-1 B with B = [[a02, a03], [a12, a13]]
    x00 = i00 * a02 + i01 * a12
    x01 = i00 * a03 + i01 * a13
    x10 = i01 * a02 + i11 * a12
    x11 = i01 * a03 + i11 * a13
    s00 = a22 - (a02 * x00 + a12 * x10)
    s01 = a23 - (a02 * x01 + a12 * x11)
    s11 = a33 - (a03 * x01 + a13 * x11)
    detS = s00 * s11 - s01 * s01
    rS = 1.0 / detS
    t00, t01, t11 = s11 * rS, -s01 * rS, s00 * rS  # S^-1
    u00 = -(x00 * t00 + x01 * t01)  # upper-right block -X S^-1
    u01 = -(x00 * t01 + x01 * t11)
    u10 = -(x10 * t00 + x11 * t01)
    u11 = -(x10 * t01 + x11 * t11)
    return (
        i00 - (u00 * x00 + u01 * x01),
        i01 - (u00 * x10 + u01 * x11),
        u00,
        u01,
        i11 - (u10 * x10 + u11 * x11),
        u10,
        u11,
        t00,
        t01,
        t11,
    ), detA * detS


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
    Ct = np.moveaxis(C, (-2, -1), (0, 1))  # entries as contiguous-ish slabs
    entries, det = sym4_inverse_entries(*(Ct[i, j] for i, j in SYM4_INDEX))
    return sym4_assemble(entries, C.shape[:-2]), det


def inv_det_spd(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of a stack of SPD matrices ``P (..., d, d)``, any ``d``."""
    d = P.shape[-1]
    if d == 2:
        return inv_det_2x2(P)
    if d == 4 and (P.ndim > 3 or P.shape[0] > 200):
        return inv_det_sym4(P)
    if d == 1:
        return 1.0 / P, P[..., 0, 0]
    inv = np.linalg.inv(P)
    return 0.5 * (inv + np.swapaxes(inv, -1, -2)), np.linalg.det(P)


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
