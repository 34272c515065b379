"""Every answer carries exactly its source's ports: empty, partial and padded answers refused."""
import numpy as np

from pentapod_sim.sim.stepping import ForceMixer, ForceSource

PORTS = ['tcp_force_x', 'tcp_force_y', 'tcp_force_z']


def test_an_empty_or_partial_answer_cannot_displace_the_real_one():
    """The forged answers come first at the right stamp; the real one is still applied."""
    mixer = ForceMixer(PORTS, [ForceSource('damper', ('tcp_force_x', 'tcp_force_y'))])
    assert mixer.submit('damper', [], [], 0, 0).startswith('ports: an empty answer')
    assert 'lacks' in mixer.submit('damper', ['tcp_force_x'], [1e5], 0, 0)
    assert 'forbidden_port' in mixer.submit('damper', PORTS, [1.0, 2.0, 3.0], 0, 0)
    assert mixer.submit('damper', ['tcp_force_y', 'tcp_force_x'], [2.0, 1.0], 0, 0) is None
    assert np.array_equal(mixer.latest['damper'], [1.0, 2.0, 0.0])
    assert mixer.rejected[('damper', 'ports')] == 2
    assert mixer.rejected_at(0, ['damper'])['damper'].startswith('forbidden_port')


def test_an_unconfigured_source_keeps_the_ports_of_its_first_answer():
    mixer = ForceMixer(PORTS, [ForceSource('exciter')])
    assert mixer.submit('exciter', [], [], 0, 0) is not None          # never an empty one
    assert mixer.submit('exciter', ['tcp_force_z'], [5.0], 0, 0) is None
    assert 'empty' in mixer.submit('exciter', [], [], 1, 1)
    assert 'adds' in mixer.submit('exciter', ['tcp_force_z', 'tcp_force_x'], [1e5, 1e5], 1, 1)
    assert 'duplicate_port' in mixer.submit('exciter', ['tcp_force_z', 'tcp_force_z'],
                                            [1.0, 1.0], 1, 1)
    assert mixer.submit('exciter', ['tcp_force_z'], [6.0], 1, 1) is None
    assert np.array_equal(mixer.latest['exciter'], [0.0, 0.0, 6.0])
    assert mixer.accepted['exciter'] == 2
