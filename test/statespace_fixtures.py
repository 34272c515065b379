"""Small random FE models with every named point, for the port/reduction/state-space tests."""
import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from pentapod_sim.fe.model import FEModel

POINT_NAMES = (['tcp', 'pma_mount'] + [f'bp_ring{i}' for i in range(1, 6)]
               + [f'strut{i}_{p}' for i in range(1, 6) for p in ('wp_end', 'rear_end', 'at_bp')])


def random_frames(rng: np.random.Generator) -> np.ndarray:
    """Five random right-handed orthonormal frames (rows e1, e2, e3)."""
    frames = np.empty((5, 3, 3))
    for i in range(5):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        frames[i] = q.T * np.sign(np.linalg.det(q))
    return frames


def small_model(seed: int = 0, n_extra_nodes: int = 4) -> FEModel:
    """
    A 6-DOF-per-node chain of random springs and masses, grounded at node 0.

    Every named point of docs/architecture.md sits on its own node; the stiffness is a
    random symmetric positive definite matrix [N/m], the mass a random SPD matrix [kg].
    """
    rng = np.random.default_rng(seed)
    n_nodes = len(POINT_NAMES) + n_extra_nodes
    n = 6 * n_nodes
    k = np.zeros((n, n))
    for a in range(n_nodes - 1):          # springs between neighbouring nodes
        b = a + 1
        root = rng.normal(size=(6, 6))
        block = 1e6 * (root @ root.T + 6 * np.eye(6))
        ia, ib = slice(6 * a, 6 * a + 6), slice(6 * b, 6 * b + 6)
        k[ia, ia] += block
        k[ib, ib] += block
        k[ia, ib] -= block
        k[ib, ia] -= block
    k[:6, :6] += 1e7 * np.eye(6)          # ground
    for a in rng.choice(n_nodes, 5, replace=False):   # a few cross links
        b = rng.integers(n_nodes)
        if a != b:
            block = 2e5 * np.eye(6)
            ia, ib = slice(6 * a, 6 * a + 6), slice(6 * b, 6 * b + 6)
            k[ia, ia] += block
            k[ib, ib] += block
            k[ia, ib] -= block
            k[ib, ia] -= block
    root = rng.normal(size=(n, n)) * 0.05
    m = root @ root.T + np.diag(rng.uniform(1.0, 5.0, n))
    perm = rng.permutation(n_nodes)
    nodes, spare = perm[:len(POINT_NAMES)], perm[len(POINT_NAMES):]
    # one inner node on each strut's active span (chord ports), on the spare nodes
    named = list(zip(POINT_NAMES, nodes)) + [
        (f'strut{i}_span1', spare[(i - 1) % len(spare)]) for i in range(1, 6)]
    points = {}
    for name, node in named:
        points[name] = sp.csr_matrix((np.ones(6), (np.arange(6), 6 * node + np.arange(6))),
                                     shape=(6, n))
    frames = random_frames(rng)
    k, m, drives = _with_gimbals(k, m, points, frames)
    n = k.shape[0]
    points = {name: sp.csr_matrix((t.data, t.indices, t.indptr), shape=(6, n))
              for name, t in points.items()}
    for i in range(1, 6):
        node = n // 6 - 6 + i
        points[f'gimbal{i}'] = sp.csr_matrix((np.ones(6), (np.arange(6),
                                                           6 * node + np.arange(6))),
                                             shape=(6, n))
    K = sp.csr_matrix(k)
    return FEModel(K=K, M=sp.csr_matrix(m),
                   stiffness_groups={'frame': K - sp.csr_matrix(drives),
                                     'feed_drives': sp.csr_matrix(drives)},
                   points=points, point_positions={p: np.zeros(3) for p in points},
                   strut_frames=frames)


def _with_gimbals(k: np.ndarray, m: np.ndarray, points: dict, frames: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Append five gimbal nodes with feed-drive links.

    Each hangs on its strut's ``at_bp`` node by a feed-drive link
    (axial spring k_a along e1 and stiff lateral/rotational springs, the 'feed_drives' group)
    and on the model's first node by a spring; returns K, M and the feed-drive stiffness.
    """
    rng = np.random.default_rng(99)
    n0 = k.shape[0]
    n = n0 + 30
    k_all, m_all, drives = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    k_all[:n0, :n0], m_all[:n0, :n0] = k, m
    for i in range(1, 6):
        g = slice(n0 + 6 * (i - 1), n0 + 6 * i)
        s = slice(*(points[f'strut{i}_at_bp'].indices[[0, -1]] + [0, 1]))
        big = np.kron(np.eye(2), frames[i - 1])
        link = big.T @ np.diag([rng.uniform(2e6, 8e6)] + [5e7] * 5) @ big
        for a, b, sign in ((s, s, 1), (g, g, 1), (s, g, -1), (g, s, -1)):
            drives[a, b] += sign * link
        k_all[g, g] += 3e6 * np.eye(6)
        k_all[g, :6] -= 3e6 * np.eye(6)
        k_all[:6, g] -= 3e6 * np.eye(6)
        k_all[:6, :6] += 3e6 * np.eye(6)
        m_all[g, g] = np.diag(rng.uniform(1.0, 3.0, 6))
    return k_all + drives, m_all, drives


def all_modes(model: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """All modes by dense eigh: angular frequencies [rad/s] and mass-normalised shapes."""
    lam, phi = la.eigh(model.K.toarray(), model.M.toarray())
    return np.sqrt(lam), phi
