"""Chord damper ports (lateral motion of a strut point against its chord) and the damping model."""
import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
from statespace_fixtures import small_model

from pentapod_sim.errors import PortError
from pentapod_sim.plant import ports
from pentapod_sim.plant.build import load_reduction_config, modal_damping, plant_from_fe
from pentapod_sim.plant.config import DampingGroup

N_SPAN = 4          # elements on the active span of the synthetic strut
LENGTH = 1.2        # m, BP joint to WP joint


def _straight_strut():
    """Points of a straight strut 1 along global x (one node per point, 6 DOFs each)."""
    names = (['strut1_at_bp'] + [f'strut1_span{j}' for j in range(1, N_SPAN)]
             + ['strut1_wp_end'])
    n = 6 * len(names)
    points = {name: sp.csr_matrix((np.ones(6), (np.arange(6), 6 * i + np.arange(6))),
                                  shape=(6, n)) for i, name in enumerate(names)}
    x = np.linspace(0.0, LENGTH, N_SPAN + 1)
    frames = np.tile(np.eye(3), (5, 1, 1))      # e1 = x, e2 = y, e3 = z
    return points, frames, x


def _field(x, translation, rotation=lambda s: np.zeros((len(s), 3))):
    """DOF vector from nodal translations (N, 3) and rotations (N, 3) at positions x."""
    return np.hstack([translation, rotation(x)]).ravel()


@pytest.mark.parametrize('position', [0.5, 0.3, 0.9])
def test_rigid_motion_of_the_strut_gives_no_chord_signal(position):
    points, frames, x = _straight_strut()
    xyz = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    t, theta = np.array([1e-3, -2e-3, 3e-3]), np.array([0.01, -0.02, 0.03])
    u = _field(x, t + np.cross(theta, xyz), lambda s: np.tile(theta, (len(s), 1)))
    for k in (2, 3):
        p = ports.port(points, frames, f'strut1_chord_{k}', position)
        assert p.vector @ u == pytest.approx(0.0, abs=1e-15)


def test_bending_shape_reads_its_deflection_at_the_chord_point():
    """
    A sine bending shape along e2 plus a rigid tilt: the port reads the sine at the point.

    Exact at a node, linear interpolation between nodes.
    """
    points, frames, x = _straight_strut()
    s = x / LENGTH
    w = 1e-4 * np.sin(np.pi * s) + 5e-4 * s
    u = _field(x, np.column_stack([np.zeros_like(x), w, np.zeros_like(x)]))
    mid = ports.port(points, frames, 'strut1_chord_2', 0.5)
    assert mid.vector @ u == pytest.approx(1e-4, rel=1e-12)
    assert ports.port(points, frames, 'strut1_chord_3', 0.5).vector @ u == 0.0
    q = 0.6                                  # between nodes 2 (0.5) and 3 (0.75)
    lin = 1e-4 * (0.6 * np.sin(np.pi * 0.5) + 0.4 * np.sin(np.pi * 0.75))
    assert ports.port(points, frames, 'strut1_chord_2', q).vector @ u == pytest.approx(lin)


def test_chord_force_is_self_equilibrated_and_collocated():
    points, frames, x = _straight_strut()
    force = ports.port(points, frames, 'strut1_chord_force_3', 0.3)
    rate = ports.port(points, frames, 'strut1_chord_velocity_3', 0.3)
    np.testing.assert_array_equal(force.vector, rate.vector)
    loads = force.vector.reshape(-1, 6)[:, :3]
    assert np.allclose(loads.sum(axis=0), 0.0)                       # no net force
    xyz = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    assert np.allclose(np.cross(xyz, loads).sum(axis=0), 0.0, atol=1e-15)   # no net moment
    assert ports.collocated_output('strut1_chord_force_3') == 'strut1_chord_velocity_3'


def test_chord_port_without_span_points_is_refused():
    points, frames, _ = _straight_strut()
    with pytest.raises(PortError, match='span'):
        ports.port(points, frames, 'strut2_chord_2')
    with pytest.raises(PortError, match='chord_position'):
        ports.port(points, frames, 'strut1_chord_2', 1.5)


def test_modal_damping_groups_override_their_band_only():
    freq = np.array([10.0, 26.0, 31.0, 45.0, 80.0])
    zeta = modal_damping(freq, 0.001, [DampingGroup(20.0, 40.0, 0.006),
                                       DampingGroup(80.0, 90.0, 0.002)])
    np.testing.assert_array_equal(zeta, [0.001, 0.006, 0.006, 0.001, 0.002])


def test_damping_option_changes_the_chosen_modes_only():
    model = small_model(0)
    cfg = load_reduction_config()
    base, keep = plant_from_fe(model, cfg)
    f = base.omega / (2 * np.pi)
    lo, hi = np.sort(f)[2], np.sort(f)[5]           # a band holding modes 3..5
    groups = (DampingGroup(float(lo), float(hi), 0.012),)
    damped, keep2 = plant_from_fe(model, dataclasses.replace(cfg, damping_groups=groups))
    inside = (f >= lo) & (f < hi)
    assert inside.sum() == 3
    np.testing.assert_array_equal(damped.zeta[inside], 0.012)
    np.testing.assert_array_equal(damped.zeta[~inside], base.zeta[~inside])
    np.testing.assert_array_equal(damped.omega, base.omega)
    np.testing.assert_array_equal(damped.b, base.b)
    np.testing.assert_array_equal(keep, keep2)
    assert cfg.damping_groups == ()          # shipped default: off, 0.1 % everywhere
    assert np.all(base.zeta == cfg.damping_ratio)
