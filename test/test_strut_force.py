"""
Strut force outputs: the load cell in series with the feed drive (``strut<i>_force``).

Checked against the link's own spring law on a small model, against a static FE solve and a
direct harmonic FE solve of the machine at P1 (the force computed from the gimbal's side of
the link with the nut stiffness of config/machine.yaml, not from the load points), and that
the static correction of the truncated modes is what keeps the reduced plant's force right.
"""
import dataclasses

import numpy as np
import pytest
from statespace_fixtures import small_model

from pentapod_sim.fe.assembly import build_model
from pentapod_sim.fe.machine_data import load_machine
from pentapod_sim.plant import frf, ports, reduction
from pentapod_sim.plant.build import (
    from_modal_data,
    load_reduction_config,
    plant_from_fe,
    reduce_plant,
)

INPUTS = ('tcp_force_x', 'strut1_drive_force', 'strut2_drive_force')
OUTPUTS = ('strut1_force', 'strut1_drive_displacement', 'tcp_displacement_x')


def _points(model):
    return {**model.points, **ports.load_points(model.points, model.stiffness_groups)}


def test_link_force_is_the_spring_law_of_the_link():
    model = small_model(2)
    e1 = model.strut_frames[2, 0]
    u = np.zeros(model.n_dof)
    u += model.points['strut3_at_bp'].T @ np.r_[4e-6 * e1, 0, 0, 0]
    u += model.points['gimbal3'].T @ np.r_[1e-6 * e1, 0, 0, 0]
    force = ports.port(_points(model), model.strut_frames, 'strut3_force')
    link = model.stiffness_groups['feed_drives']
    g = model.points['gimbal3'].indices
    k_axial = e1 @ link[np.ix_(g[:3], g[:3])].toarray() @ e1      # the fixture's k_a
    assert force.unit == 'N' and force.kind == 'load'
    assert force.vector @ u == pytest.approx(-k_axial * 3e-6, rel=1e-12)
    assert force.direct == (('strut3_drive_force', 1.0),)
    drive = ports.port(model.points, model.strut_frames, 'strut3_drive_force')
    moved = ports.port(model.points, model.strut_frames, 'strut3_drive_displacement')
    np.testing.assert_array_equal(drive.vector, moved.vector)
    assert ports.collocated_output('strut3_drive_force', 'load') == 'strut3_force'


def test_direct_matrix_and_modal_data_feed_through():
    model = small_model(0)
    out = ports.ports(_points(model), model.strut_frames, ['strut2_force', 'tcp_displacement_y'])
    d = ports.direct_matrix(out, ['tcp_force_y', 'strut2_drive_force', 'strut1_drive_force'])
    np.testing.assert_array_equal(d, [[0, 1, 0], [0, 0, 0]])
    phi = np.linalg.qr(np.random.default_rng(1).normal(size=(model.n_dof, 4)))[0]
    plant = from_modal_data(np.arange(1, 5), ports.modal_points(_points(model), phi),
                            model.strut_frames, ['strut2_drive_force'], ['strut2_force'])
    assert plant.d[0, 0] == 1.0


def test_model_without_drive_links_names_what_is_missing():
    model = small_model(0)
    with pytest.raises(KeyError, match='feed_drives'):
        ports.port(model.points, model.strut_frames, 'strut4_force')


@pytest.fixture(scope='module')
def machine_p1():
    machine = load_machine()
    fe = build_model(machine, 'P1')
    cfg = load_reduction_config()
    tcp = dataclasses.replace(cfg.relevance[0], inputs=('tcp_force_x',),
                              outputs=('tcp_displacement_x',))
    drive = dataclasses.replace(cfg.relevance[0], inputs=('strut1_drive_force',),
                                outputs=('strut1_drive_displacement',), abs_limit=None,
                                rel_limit=0.01)
    cfg = dataclasses.replace(cfg, inputs=INPUTS, outputs=OUTPUTS, relevance=(tcp, drive),
                              damping_ratio=0.0)
    plant_all, keep = plant_from_fe(fe, cfg)
    return machine, fe, plant_all, keep


def _exact_force(machine, fe, response):
    """F = u_drive - k_a e1 . (u_at_bp - u_gimbal), from displacement rows of the FE solve."""
    return np.array([0.0, 1.0, 0.0])[:, None] - (
        machine.feed_drives.nut_axial_stiffness * response)


def _drive_rows(fe):
    b = ports.input_matrix(ports.ports(fe.points, fe.strut_frames, INPUTS))
    e1 = fe.strut_frames[0, 0]
    c = e1 @ (fe.points['strut1_at_bp'] - fe.points['gimbal1'])[:3].toarray()
    return b, c[None, :]


def test_static_force_equals_static_fe_solve(machine_p1):
    machine, fe, plant_all, keep = machine_p1
    b, c = _drive_rows(fe)
    exact = _exact_force(machine, fe, reduction.static_compliance(fe.K, b, c).T)[:, 0]
    for corrected in (True, False):
        plant = reduce_plant(plant_all, keep, corrected)
        a, bb, cc, d = plant.state_matrices()
        static = (d - cc @ np.linalg.solve(a, bb))[0]
        if corrected:
            np.testing.assert_allclose(static, exact, rtol=1e-7, atol=1e-9)
        else:         # truncation alone: the drive's own force is off by far more than 1e-7
            assert abs(static[1] - exact[1]) > 1e-2
    # a TCP force of 1 N along x loads strut 1 with most of a newton (statics of the legs)
    assert 0.5 < abs(exact[0]) < 2.0


def test_force_frf_equals_full_model_harmonic_solve(machine_p1):
    machine, fe, plant_all, keep = machine_p1
    b, c = _drive_rows(fe)
    freq = reduction.between_resonances(plant_all.frequencies_hz, 400.0)[::5]
    exact = _exact_force(machine, fe, reduction.harmonic_response(fe.K, fe.M, b, c, freq)[0])
    everything = frf.modal_frf(plant_all, freq).H[0]
    scale = np.abs(exact).max(axis=1, keepdims=True)
    # every mode below 750 Hz and the residual flexibility of those above: the residual is
    # static, so the error grows towards 400 Hz (0.7 % of the peak there, 1e-5 at 10 Hz)
    error = np.abs(everything - exact) / scale
    assert error.max() < 1e-2 and error[:, 0].max() < 1e-4
    # the reduced plant: with the static correction its collocated force FRF (the IFF plant)
    # is an order of magnitude closer to the full model than the truncated modes alone
    errors = []
    for corrected in (True, False):
        h = frf.modal_frf(reduce_plant(plant_all, keep, corrected), freq).H[0, 1]
        errors.append(np.median(np.abs(h - exact[1]) / np.abs(exact[1])))
    assert errors[0] < errors[1] / 10
