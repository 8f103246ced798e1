"""Closed-form batched inverses and determinants (tracking.gaussian) against numpy.linalg."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.tracking.gaussian import (
    SYM4_INDEX,
    gaussian_pdf_points,
    inv_det_2x2,
    inv_det_spd,
    inv_det_sym4,
    log_gaussian,
    quad_form,
    sym4_assemble,
    symmetrise,
)


def random_spd(rng: np.random.Generator, shape: tuple[int, ...], d: int) -> np.ndarray:
    """Random SPD stack ``(*shape, d, d)``: condition numbers up to ~1e3, mixed scales."""
    A = rng.normal(size=(*shape, d, d))
    Q, _ = np.linalg.qr(A)
    eig = 10.0 ** rng.uniform(-1.5, 1.5, size=(*shape, d))
    P = np.einsum("...ij,...j,...kj->...ik", Q, eig, Q)
    scale = 10.0 ** rng.uniform(-1, 3, size=(*shape, 1, 1))
    return symmetrise(P * scale)


SHAPES = [(), (1,), (7,), (3, 5), (2, 3, 4), (250,)]


@pytest.mark.parametrize("shape", SHAPES)
def test_inv_det_2x2_matches_numpy(shape):
    rng = np.random.default_rng(len(shape) * 1000 + int(np.prod(shape)))
    S = random_spd(rng, shape, 2)
    inv, det = inv_det_2x2(S)
    assert inv.shape == S.shape and np.shape(det) == shape
    np.testing.assert_allclose(inv, np.linalg.inv(S), rtol=1e-9, atol=0)
    np.testing.assert_allclose(det, np.linalg.det(S), rtol=1e-10)


def test_inv_det_2x2_non_symmetric():
    # The adjugate form does not need symmetry.
    rng = np.random.default_rng(1)
    S = rng.normal(size=(20, 2, 2)) + 3 * np.eye(2)
    inv, det = inv_det_2x2(S)
    np.testing.assert_allclose(inv, np.linalg.inv(S), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(det, np.linalg.det(S), rtol=1e-10)


@pytest.mark.parametrize("shape", SHAPES)
def test_inv_det_sym4_matches_numpy(shape):
    rng = np.random.default_rng(100 + len(shape) + int(np.prod(shape)))
    C = random_spd(rng, shape, 4)
    inv, det = inv_det_sym4(C)
    assert inv.shape == C.shape and np.shape(det) == shape
    ref = np.linalg.inv(C)
    # relative to the size of the inverse (conditioning up to ~1e3)
    scale = np.abs(ref).max(axis=(-2, -1), keepdims=True)
    assert np.all(np.abs(inv - ref) <= 1e-9 * scale)
    np.testing.assert_allclose(det, np.linalg.det(C), rtol=1e-9)
    np.testing.assert_allclose(inv, np.swapaxes(inv, -1, -2), rtol=0, atol=0)
    eye = np.broadcast_to(np.eye(4), C.shape)
    np.testing.assert_allclose(inv @ C, eye, atol=1e-8)


@pytest.mark.parametrize("d", [1, 2, 3, 4, 6])
@pytest.mark.parametrize("shape", [(5,), (300,), (4, 6)])
def test_inv_det_spd_any_dimension(d, shape):
    rng = np.random.default_rng(7 * d + len(shape))
    P = random_spd(rng, shape, d)
    inv, det = inv_det_spd(P)
    ref = np.linalg.inv(P)
    scale = np.abs(ref).max(axis=(-2, -1), keepdims=True)
    assert np.all(np.abs(inv - ref) <= 1e-9 * scale)
    np.testing.assert_allclose(det, np.linalg.det(P), rtol=1e-9)


def test_sym4_assemble_symmetric_and_placed():
    rng = np.random.default_rng(3)
    shape = (3, 5)
    entries = [rng.normal(size=shape) for _ in SYM4_INDEX]
    M = sym4_assemble(entries, shape)
    assert M.shape == (*shape, 4, 4)
    np.testing.assert_array_equal(M, np.swapaxes(M, -1, -2))
    for (i, j), e in zip(SYM4_INDEX, entries, strict=True):
        np.testing.assert_array_equal(M[..., i, j], e)
        np.testing.assert_array_equal(M[..., j, i], e)


def test_sym4_assemble_broadcasts_scalars_and_rows():
    shape = (2, 3)
    entries = [float(k) for k in range(10)]
    entries[0] = np.arange(3.0)[None, :]  # broadcast along the first axis
    M = sym4_assemble(entries, shape)
    np.testing.assert_array_equal(M[..., 0, 0], np.broadcast_to(np.arange(3.0), shape))
    np.testing.assert_array_equal(M[..., 3, 3], np.full(shape, 9.0))
    np.testing.assert_array_equal(M, np.swapaxes(M, -1, -2))


def test_log_gaussian_and_pdf_match_scipy():
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(5)
    for d in (2, 4):
        covs = random_spd(rng, (6,), d)
        means = rng.normal(size=(6, d)) * 5
        x = rng.normal(size=(9, d)) * 5
        pdf = gaussian_pdf_points(x, means, covs)
        ref = np.stack(
            [multivariate_normal(means[j], covs[j]).pdf(x) for j in range(6)], axis=1
        )
        np.testing.assert_allclose(pdf, ref, rtol=1e-8, atol=1e-300)
        inv, det = inv_det_spd(covs)
        diff = x[:, None] - means[None]
        ref_log = np.stack(
            [multivariate_normal(means[j], covs[j]).logpdf(x) for j in range(6)], axis=1
        )
        np.testing.assert_allclose(log_gaussian(diff, inv[None], det[None]), ref_log, rtol=1e-9)
        q = quad_form(diff, inv[None])
        ref_q = np.einsum("pni,nij,pnj->pn", diff, np.linalg.inv(covs), diff)
        np.testing.assert_allclose(q, ref_q, rtol=1e-8)
