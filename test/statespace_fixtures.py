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
    K = sp.csr_matrix(k)
    return FEModel(K=K, M=sp.csr_matrix(m), stiffness_groups={'frame': K}, points=points,
                   point_positions={p: np.zeros(3) for p in points},
                   strut_frames=random_frames(rng))


def all_modes(model: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """All modes by dense eigh: angular frequencies [rad/s] and mass-normalised shapes."""
    lam, phi = la.eigh(model.K.toarray(), model.M.toarray())
    return np.sqrt(lam), phi
