"""The faster paths of the dense estimator compute what the plain formulas do: the surfels'
moments of the changed cells alone, the points mapped in chunks, the derivatives along a
normal (through the rotations' axial vectors, not their complex step) and the consensus'
misfits of all hypotheses at once."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tumblescan.linescan.dense import mapping as mapping_module
from tumblescan.linescan.dense.consensus import pair_misfits
from tumblescan.linescan.dense.data import prepare
from tumblescan.linescan.dense.mapping import LineMapping, _rotations_T
from tumblescan.linescan.dense.surfels import _cell_moments
from tumblescan.numerics.derivatives import complex_step
from tumblescan.target.motion import rotation_matrices

X = np.array([0.3, 1.1, 0.4, -2.0, 0.7, 0.05, 0.2, -0.1, 50.0])


def _cloud(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points about 50 m away on 3 frames of 40 lines each, 200 points a line."""
    rng = np.random.default_rng(seed)
    n = 3 * 40 * 200
    xyz = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), 50 + rng.normal(0, 0.3, n)])
    tau = np.repeat(np.arange(3 * 40) * 0.01, 200)
    return xyz, tau, np.repeat(np.arange(3), 40 * 200)


def test_moments_of_the_changed_cells_alone_equal_the_full_ones_to_the_bit() -> None:
    xyz, tau, frame = _cloud(1)
    data = prepare(xyz, tau, frame, surfel_m=0.2)
    mapping = LineMapping(X, data.tau_s, tuple(range(9)))
    mapped = mapping.apply_about_center(data.xyz_m, data.line)
    m = len(data.cell_frame)
    # Points handed to other cells, as assign_to_faces does: some cells gain, some lose.
    rng = np.random.default_rng(2)
    point_cell = data.cell.copy()
    moved = rng.choice(len(point_cell), 500, replace=False)
    point_cell[moved] = rng.integers(0, m, len(moved))
    changed = np.zeros(m, dtype=bool)
    changed[point_cell[moved]] = changed[data.cell[moved]] = True
    full = _cell_moments(data, mapped, point_cell, m)
    only = _cell_moments(data, mapped, point_cell, m, only=changed)
    for whole, part in zip(full, only, strict=True):
        np.testing.assert_array_equal(part[changed], whole[changed])
    # The cached counts and lines of the cells' own points are those computed afresh.
    own = _cell_moments(data, mapped, data.cell, m)
    fresh = _cell_moments(data, mapped, data.cell.copy(), m)
    for cached, computed in zip(own, fresh, strict=True):
        np.testing.assert_array_equal(cached, computed)


def test_points_mapped_in_chunks_equal_the_gathered_rotations(monkeypatch: pytest.MonkeyPatch) -> None:
    xyz, tau, frame = _cloud(3)
    data = prepare(xyz, tau, frame, surfel_m=0.2)
    mapping = LineMapping(X, data.tau_s, tuple(range(9)))
    c = mapping.center
    expected = c + np.einsum("nij,nj->ni", mapping.Rt[data.line], xyz - c)
    whole = mapping.apply(data.xyz_m, data.line)
    monkeypatch.setattr(mapping_module, "APPLY_CHUNK", 777)  # many chunks, the last one short
    chunked = mapping.apply(data.xyz_m, data.line)
    np.testing.assert_array_equal(chunked, whole)
    np.testing.assert_allclose(whole, expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(mapping.apply_about_center(data.xyz_m, data.line), whole - c)
    v = xyz - c
    np.testing.assert_allclose(
        mapping.rotate(v, data.line), np.einsum("nij,nj->ni", mapping.Rt[data.line], v), rtol=0, atol=1e-12
    )


@pytest.mark.parametrize("free", [tuple(range(9)), (0, 1, 2, 6, 7, 8)])
def test_derivatives_along_a_normal_equal_the_complex_step_of_the_mapping(
    free: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    tau = np.linspace(0.0, 30.0, 500)
    mapping = LineMapping(X, tau, free)
    rng = np.random.default_rng(4)
    n_rows = 3 * mapping_module.DERIVATIVE_CHUNK + 5
    line = rng.integers(0, len(tau), n_rows)
    n = rng.normal(size=(n_rows, 3))
    xyz = rng.normal(size=(n_rows, 3)) + X[6:9]

    def along_normal(xs: np.ndarray) -> np.ndarray:
        """``n . (O_p + R(tau)^T (p - O_p))`` per row, for parameter rows ``xs`` (k, 9)."""
        O = xs[:, None, 6:9]
        mapped = O + np.einsum("knab,knb->kna", _rotations_T(xs, tau)[:, line], xyz[None] - O)
        return np.asarray(np.einsum("kna,na->kn", mapped, n))

    expected = complex_step(along_normal, X, free).T
    # Through the axial vectors of R d(R^T): the same to rounding, and the chunks change no bit.
    whole = mapping.normal_derivative(n, xyz, line)
    np.testing.assert_allclose(whole, expected, rtol=0, atol=1e-13 * np.abs(expected).max())
    monkeypatch.setattr(mapping_module, "DERIVATIVE_CHUNK", 777)
    np.testing.assert_array_equal(mapping.normal_derivative(n, xyz, line), whole)


def test_misfits_of_all_hypotheses_at_once_equal_one_at_a_time() -> None:
    rng = np.random.default_rng(5)
    xs = np.column_stack(
        [
            rng.uniform(-3, 3, 50),
            rng.uniform(0, 3, 50),
            rng.uniform(0, 0.5, 50),
            rng.uniform(-3, 3, 50),
            rng.uniform(0, 3, 50),
            rng.uniform(-0.2, 0.2, 50),
            rng.normal(size=(50, 3)),
        ]
    )
    tau_from = np.linspace(0.0, 52.0, 14)
    tau_to = np.linspace(4.0, 56.0, 14)
    Rs = rotation_matrices(X, tau_to) @ np.swapaxes(rotation_matrices(X, tau_from), 1, 2)

    def one(x: np.ndarray) -> np.ndarray:
        Q = rotation_matrices(x, tau_to) @ np.swapaxes(rotation_matrices(x, tau_from), 1, 2)
        return np.linalg.norm(Rotation.from_matrix(np.swapaxes(Q, 1, 2) @ Rs).as_rotvec(), axis=1)

    np.testing.assert_allclose(
        pair_misfits(xs, Rs, tau_from, tau_to), np.array([one(x) for x in xs]), rtol=0, atol=1e-12
    )
    # The true motion explains every pair.
    assert np.max(pair_misfits(X[None, :], Rs, tau_from, tau_to)) < 1e-9
