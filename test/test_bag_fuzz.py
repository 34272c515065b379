"""
Seeded fuzz of the bag reader: random single-bit flips and truncations of a small bag.

Each trial either reads exactly the recorded data (no damage reported), or reports damage,
and then every message it returns is a recorded one with its recorded values, and the
messages it reports lost are exactly the ones it does not return. One flipped bit costs at
most the one chunk that holds it; a cut costs exactly the chunks it cuts or follows. Nothing
but BagError escapes, and no trial allocates more than a bound far below what a damaged
length field would ask for. The expectations come from the writer's inputs and from the mcap
package's own reader, not from the reader under test.
"""
import shutil
import tracemalloc
import warnings

import numpy as np
import pytest

from fixtures.bags import chunk_table, N_STEPS, recorded, returned_messages, write_bag
from pentapod_sim.analysis.bag.file_content import BagDamageWarning
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.errors import BagError

ALLOCATION_BOUND = 16 << 20  # [bytes]; the bag is about 60 kB, a damaged length asks for TBs


@pytest.fixture(scope='module')
def reference(tmp_path_factory):
    values = recorded()
    out = {}
    for compression in ('', 'zstd'):
        path = tmp_path_factory.mktemp('fuzz') / f'ref{compression}'
        write_bag(path, values, compression)
        file = path / f'{path.name}_0.mcap'
        out[compression] = (path, file.read_bytes(), chunk_table(file))
    return values, out


def _trial(path, name: str, damaged: bytes, reader: str):
    (path / name).write_bytes(damaged)
    tracemalloc.start()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            bag = open_bag(path, reader=reader)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < ALLOCATION_BOUND
    return bag, [w for w in caught if issubclass(w.category, BagDamageWarning)]


@pytest.mark.parametrize('compression,trials', [('', 200), ('zstd', 60)])
def test_random_flips_and_cuts_read_correct_data_or_report_the_loss(reference, tmp_path,
                                                                      compression, trials):
    values, refs = reference
    ref_path, data, chunks = refs[compression]
    total = 3 * N_STEPS
    trial_path = tmp_path / 'trial'
    trial_path.mkdir()
    shutil.copy(ref_path / 'metadata.yaml', trial_path)  # as a crashed recorder leaves it
    name = f'{ref_path.name}_0.mcap'
    rng = np.random.default_rng(20240 + len(compression))
    outcomes = {'exact': 0, 'damage': 0, 'unreadable': 0}
    for trial in range(trials):
        damaged = bytearray(data)
        if trial % 4 == 3:
            cut = int(rng.integers(0, len(data)))
            damaged = damaged[:cut]
            expected = {sum(c.n for c in chunks if c.end <= cut)}
        else:
            bit = int(rng.integers(0, 8 * len(data)))
            damaged[bit // 8] ^= 1 << (bit % 8)
            expected = {total} | {total - c.n for c in chunks if c.start <= bit // 8 < c.end}
        what = f'trial {trial}: ' + (f'cut at {cut}' if trial % 4 == 3 else f'bit {bit}')
        try:
            bag, warned = _trial(trial_path, name, bytes(damaged), 'fast')
        except BagError:
            assert trial % 4 == 3 and expected == {0}, what  # only a cut before any chunk
            outcomes['unreadable'] += 1
            continue
        got = returned_messages(bag, values)
        assert got in expected, what
        if not bag.damage:
            assert got == total and not warned, what
            outcomes['exact'] += 1
            continue
        assert len(warned) == 1, what
        lost = [d.messages_lost for d in bag.damage]
        assert None not in lost and sum(lost) == total - got, (what, bag.damage)
        outcomes['damage'] += 1
    assert outcomes['damage'] > trials // 2 and outcomes['exact'] > 0, outcomes


def test_fallback_reader_under_damage_returns_only_correct_messages(reference, tmp_path):
    """mcap.reader stops at the first damage, but what it returns is right and loss reported."""
    values, refs = reference
    ref_path, data, _ = refs['']
    trial_path = tmp_path / 'trial'
    trial_path.mkdir()
    shutil.copy(ref_path / 'metadata.yaml', trial_path)
    rng = np.random.default_rng(99)
    for trial in range(30):
        damaged = bytearray(data)
        if trial % 2:
            damaged = damaged[:int(rng.integers(0, len(data)))]
        else:
            bit = int(rng.integers(0, 8 * len(data)))
            damaged[bit // 8] ^= 1 << (bit % 8)
        try:
            bag, warned = _trial(trial_path, f'{ref_path.name}_0.mcap', bytes(damaged),
                                 'mcap.reader')
        except BagError:
            continue
        got = returned_messages(bag, values)
        assert bag.damage or got == 3 * N_STEPS, trial
        assert bool(warned) == bool(bag.damage), trial
