"""
`analyze recover`: bags cut or damaged like a killed writer or a bad disk leaves them.

Every damaged bag is made from a good one; what recovery must keep is computed from the good
file with the mcap package's own reader and indexes (fixtures.bags), never from the code under
test, and every recovered bag is opened by rosbags (``AnyReader``) and by mcap
(``make_reader``: summary and ``iter_messages``). A kept message must be byte-identical to the
original one (data, log and publish time, sequence); what is not kept must be reported.
"""
import shutil

from mcap.reader import make_reader
import numpy as np
import pytest
import yaml

from fixtures.bags import chunk_table, message_layout, N_STEPS, recorded, write_bag
from pentapod_sim.analysis.bag.mcap_chunks import prefix_bytes, RecordDamage
from pentapod_sim.cli import analyze
from pentapod_sim.errors import BagError
from pentapod_sim.recording.recover import ORIGINALS, recover_bag, RECOVERY_RECORD

TOPICS = ('/pentapod/tcp_state', '/pentapod/excitation', '/clock')


@pytest.fixture(scope='module')
def good(tmp_path_factory):
    """Closed bags with 2 kB chunks: per compression, (folder, bytes, chunks, messages, ends)."""
    values, out = recorded(), {}
    for compression in ('', 'zstd', 'lz4'):
        path = tmp_path_factory.mktemp('good') / f'ref{compression}'
        write_bag(path, values, compression)
        file = path / f'{path.name}_0.mcap'
        out[compression] = (path, file.read_bytes(), chunk_table(file), *message_layout(file))
    return out


def damaged_bag(good, tmp_path, data: bytes, compression: str = '', name: str = 'run'):
    """A bag folder holding ``data`` and the good bag's metadata.yaml (its final counts)."""
    folder = tmp_path / name
    folder.mkdir()
    meta = (good[compression][0] / 'metadata.yaml').read_text()
    (folder / 'metadata.yaml').write_text(meta.replace(f'{good[compression][0].name}_0.mcap',
                                                       f'{name}_0.mcap'))
    (folder / f'{name}_0.mcap').write_bytes(data)
    return folder


def read_back(folder) -> list:
    """Messages of a recovered bag as mcap reads them; checks rosbags and the summary agree."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    files = sorted(folder.glob('*.mcap'))
    assert len(files) == 1
    with open(files[0], 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        got = [(c.topic, m.log_time, m.data, m.publish_time, m.sequence)
               for _, c, m in reader.iter_messages(log_time_order=False)]
    counts = {c.topic: summary.statistics.channel_message_counts.get(k, 0)
              for k, c in summary.channels.items()}
    with AnyReader([folder], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as bag:
        seen = [(c.topic, t) for c, t, raw in bag.messages()]
        for c, _, raw in list(bag.messages())[:5]:
            bag.deserialize(raw, c.msgtype)
    assert sorted(seen) == sorted((t, log) for t, log, *_ in got)
    assert counts == {t: sum(1 for g in got if g[0] == t) for t in counts}
    meta = yaml.safe_load((folder / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    listed = {e['topic_metadata']['name']: e['message_count']
              for e in meta['topics_with_message_count']}
    assert listed == counts and meta['message_count'] == len(got)
    return got


def as_rows(messages) -> list:
    return [(m.topic, m.log_time, m.data, m.publish_time, m.sequence) for m in messages]


def kept_per_topic(got) -> dict:
    return {t: sum(1 for g in got if g[0] == t) for t in TOPICS}


def data_end(good, compression=''):
    """Where the data section of the good file ends (after the last chunk's indexes)."""
    return good[compression][4][-1]


@pytest.mark.parametrize('where', ['chunk 0 header', 'chunk 0 records', 'after chunk 3',
                                   'index of chunk 3', 'chunk 7 records', 'chunk 7 last byte',
                                   'data end', 'summary', 'footer'])
def test_a_cut_keeps_every_complete_record_and_counts_the_loss(good, tmp_path, where):
    path, data, chunks, messages, ends = good['']
    cut = {'chunk 0 header': chunks[0].start + 20,
           'chunk 0 records': (chunks[0].start + chunks[0].end) // 2,
           'after chunk 3': ends[3], 'index of chunk 3': ends[3] - 7,
           'chunk 7 records': (chunks[7].start + chunks[7].end) // 2,
           'chunk 7 last byte': chunks[7].end - 1, 'data end': data_end(good),
           'summary': len(data) - 200, 'footer': len(data) - 10}[where]
    recovery = recover_bag(damaged_bag(good, tmp_path, data[:cut]))
    got = read_back(recovery.output)
    expected = [m for m in messages if m.end <= cut]     # the records complete before the cut
    assert got == as_rows(expected)
    in_cut_chunk = [m for m in expected if chunks[m.chunk].end > cut]
    for topic, entry in recovery.topics.items():
        assert entry.kept == sum(1 for m in expected if m.topic == topic)
        assert entry.unverified == sum(1 for m in in_cut_chunk if m.topic == topic)
        assert entry.lost == N_STEPS - entry.kept       # metadata.yaml of the closed bag: 120
        # only a cut after the data section's end proves that nothing more was written
        assert entry.lost_exact == (where in ('summary', 'footer'))
    assert not recovery.intact
    assert (recovery.damage[-1].end, recovery.damage[-1].start <= cut) == (cut, True)
    if in_cut_chunk:
        assert 'not CRC-checkable' in recovery.describe()


@pytest.mark.parametrize('compression', ['zstd', 'lz4'])
def test_a_cut_compressed_chunk_keeps_what_decodes_and_never_wrong_data(good, tmp_path,
                                                                        compression):
    path, data, chunks, messages, ends = good[compression]
    for k, cut in enumerate([chunks[5].start + 60, (chunks[5].start + chunks[5].end) // 2,
                             chunks[5].end - 3, chunks[5].end]):
        recovery = recover_bag(damaged_bag(good, tmp_path, data[:cut], compression, f'c{k}'))
        got = read_back(recovery.output)
        complete = as_rows(m for m in messages if m.chunk < 5)
        assert got[:len(complete)] == complete
        assert got[len(complete):] == as_rows(messages[len(complete):len(got)])
        assert len(got) == len(complete) or cut >= chunks[5].end - 3


@pytest.mark.parametrize('compression', ['', 'zstd', 'lz4'])
def test_a_cut_compressed_stream_gives_its_whole_blocks_and_no_more(compression):
    """The 2 kB chunks above are one block each; a 600 kB chunk has several (zstd 128 kB)."""
    import lz4.frame
    import zstandard
    raw = np.random.default_rng(3).bytes(600 * 1024)      # incompressible: blocks stored whole
    packed = {'': raw, 'zstd': zstandard.ZstdCompressor().compress(raw),
              'lz4': lz4.frame.compress(raw)}[compression]
    for fraction in (0.3, 0.6, 0.95):
        present = packed[:int(len(packed) * fraction)]
        out = prefix_bytes(compression, present, len(raw))
        assert raw.startswith(out)
        assert len(out) > len(present) - 130 * 1024      # at most one block is incomplete
    assert prefix_bytes(compression, packed[:len(packed) // 2], 1000) == raw[:1000]
    if compression:
        with pytest.raises(RecordDamage, match='prefix undecodable'):
            prefix_bytes(compression, b'\x00' * 64, len(raw))
    with pytest.raises(RecordDamage, match="compression 'bz2' is not supported"):
        prefix_bytes('bz2', packed, len(raw))


@pytest.mark.parametrize('compression', ['', 'zstd'])
def test_a_flipped_bit_in_a_chunk_costs_that_chunk_and_says_how_many(good, tmp_path,
                                                                   compression):
    path, data, chunks, messages, ends = good[compression]
    damaged = bytearray(data[:data_end(good, compression)])          # no summary, no footer
    damaged[(chunks[4].start + chunks[4].end) // 2] ^= 0x10
    recovery = recover_bag(damaged_bag(good, tmp_path, bytes(damaged), compression))
    got = read_back(recovery.output)
    assert got == as_rows(m for m in messages if m.chunk != 4)
    hit = [d for d in recovery.damage if 'damaged chunk skipped' in d.reason]
    assert [(d.start, d.end) for d in hit] == [(chunks[4].start, chunks[4].end)]
    assert hit[0].lost == chunks[4].counts                   # from its Message Index records
    assert (hit[0].start_ns, hit[0].end_ns) == (chunks[4].start_ns, chunks[4].end_ns)


@pytest.mark.parametrize('field', ['length', 'opcode', 'records length'])
def test_broken_framing_is_bridged_to_the_next_intact_chunk(good, tmp_path, field):
    """A damaged length or opcode: the rest is kept (``mcap recover``, Go, stops at a length)."""
    path, data, chunks, messages, ends = good['']
    damaged = bytearray(data[:data_end(good)])
    at = {'length': chunks[4].start + 6, 'opcode': chunks[4].start,
          'records length': chunks[4].start + 9 + 32 + 3}[field]
    damaged[at] ^= 0x40 if field != 'opcode' else 0x01
    recovery = recover_bag(damaged_bag(good, tmp_path, bytes(damaged)))
    got = read_back(recovery.output)
    assert got == as_rows(m for m in messages if m.chunk != 4)
    lost = [d for d in recovery.damage if d.start == chunks[4].start]
    assert len(lost) == 1 and lost[0].end in (chunks[4].end, chunks[5].start)
    assert recovery.topics[TOPICS[0]].lost >= chunks[4].counts[TOPICS[0]]


def test_a_zero_filled_tail_is_reported_as_such(good, tmp_path):
    path, data, chunks, messages, ends = good['']
    damaged = data[:ends[6]] + bytes(data_end(good) - ends[6])
    recovery = recover_bag(damaged_bag(good, tmp_path, damaged))
    assert read_back(recovery.output) == as_rows(m for m in messages if m.chunk <= 6)
    assert 'all zero bytes' in recovery.damage[-1].reason
    assert (recovery.damage[-1].start, recovery.damage[-1].end) == (ends[6], len(damaged))


def test_an_intact_bag_is_copied_exactly_with_its_records(good, tmp_path):
    path, data, chunks, messages, ends = good['']
    recovery = recover_bag(path, tmp_path / 'copy')
    assert recovery.intact and 'intact, nothing lost' in recovery.describe()
    assert read_back(tmp_path / 'copy') == as_rows(messages)
    with open(tmp_path / 'copy' / 'copy_0.mcap', 'rb') as stream:
        reader = make_reader(stream)
        records = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        profile = reader.get_header().profile
    with open(path / 'ref_0.mcap', 'rb') as stream:
        original = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
    assert profile == 'ros2'
    assert records['pentapod_run'] == original['pentapod_run']
    assert records[RECOVERY_RECORD]['damage'] == 'none'
    meta = yaml.safe_load((tmp_path / 'copy' / 'metadata.yaml').read_text())
    info = meta['rosbag2_bagfile_information']
    assert yaml.safe_load(records['rosbag2']['serialized_metadata']) == info
    old = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert {k: v for k, v in info['custom_data'].items() if not k.startswith(RECOVERY_RECORD)} \
        == old['custom_data']
    assert [t['topic_metadata'] for t in info['topics_with_message_count']] == \
        [t['topic_metadata'] for t in old['topics_with_message_count']]


def test_random_flips_and_cuts_never_crash_and_never_change_a_message(good, tmp_path):
    """Seeded: each trial keeps only original messages, in order; the rest is reported."""
    path, data, chunks, messages, ends = good['']
    source = data[:data_end(good)]
    original = as_rows(messages)
    rng = np.random.default_rng(2025)
    outcomes = {'cut': 0, 'flip': 0, 'unreadable': 0}
    for trial in range(80):
        damaged = bytearray(source)
        if trial % 3 == 2:
            damaged = damaged[:int(rng.integers(0, len(source)))]
        else:
            bit = int(rng.integers(0, 8 * len(source)))
            damaged[bit // 8] ^= 1 << (bit % 8)
        try:
            recovery = recover_bag(damaged_bag(good, tmp_path, bytes(damaged), name=f't{trial}'))
        except BagError as err:
            assert len(damaged) < chunks[0].start or 'not an MCAP file' in str(err), trial
            outcomes['unreadable'] += 1
            continue
        got = read_back(recovery.output) if trial % 8 == 0 else _mcap_rows(recovery.output)
        positions = [original.index(row) for row in got]          # each one is an original
        assert positions == sorted(set(positions)), trial          # in order, no repeat
        missing = len(original) - len(got)
        assert bool(missing) <= bool(recovery.damage), trial
        assert sum(e.lost for e in recovery.topics.values()) >= missing - sum(
            n for d in recovery.damage if d.reason.startswith('messages on channels')
            for n in d.lost.values()), trial
        outcomes['cut' if trial % 3 == 2 else 'flip'] += 1
    assert outcomes['flip'] > 40 and outcomes['cut'] > 15, outcomes


def _mcap_rows(folder) -> list:
    with open(next(folder.glob('*.mcap')), 'rb') as stream:
        return [(c.topic, m.log_time, m.data, m.publish_time, m.sequence)
                for _, c, m in make_reader(stream).iter_messages(log_time_order=False)]


def test_unverified_records_can_be_dropped(good, tmp_path):
    path, data, chunks, messages, ends = good['']
    cut = (chunks[7].start + chunks[7].end) // 2
    recovery = recover_bag(damaged_bag(good, tmp_path, data[:cut]), keep_unverified=False)
    assert read_back(recovery.output) == as_rows(m for m in messages if m.chunk < 7)
    assert all(t.unverified == 0 for t in recovery.topics.values())
    assert 'dropped' in recovery.damage[-1].reason


def test_in_place_moves_the_originals_aside(good, tmp_path):
    path, data, chunks, messages, ends = good['']
    bag = damaged_bag(good, tmp_path, data[:ends[9]])
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    recovery = recover_bag(bag, in_place=True)
    assert recovery.output == bag
    assert {p.name: p.read_bytes() for p in (bag / ORIGINALS).iterdir()} == before
    assert read_back(bag) == as_rows(m for m in messages if m.chunk <= 9)
    assert sorted(p.name for p in bag.iterdir()) == [ORIGINALS, 'metadata.yaml', 'run_0.mcap']
    with pytest.raises(BagError, match='recovered in place before'):
        recover_bag(bag, in_place=True)


def test_bad_input_gives_one_line_errors(good, tmp_path, capsys):
    path, data, *_ = good['']
    (tmp_path / 'text').mkdir()
    (tmp_path / 'text' / 'x.mcap').write_text('name: value\n' * 100)
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'empty' / 'e.mcap').write_bytes(b'')
    (tmp_path / 'busy').mkdir()
    (tmp_path / 'busy' / 'file').write_text('')
    cases = {tmp_path / 'nothing': 'no bag at', tmp_path / 'text': 'not an MCAP file',
             tmp_path / 'empty': 'is empty'}
    for bag, message in cases.items():
        with pytest.raises(BagError, match=message):
            recover_bag(bag)
    with pytest.raises(BagError, match='exists and is not empty'):
        recover_bag(path, tmp_path / 'busy')
    assert analyze.main(['recover', str(tmp_path / 'text')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('analyze: error: ') and 'x.mcap' in err


def test_the_command_reports_and_writes_the_bag(good, tmp_path, capsys):
    path, data, chunks, messages, ends = good['']
    bag = damaged_bag(good, tmp_path, data[:ends[9]])
    assert analyze.main(['recover', str(bag), '--dry-run']) == 0
    assert 'dry run' in capsys.readouterr().out and not (tmp_path / 'run-recovered').exists()
    assert analyze.main(['recover', str(bag), '--to', str(tmp_path / 'fixed')]) == 0
    out = capsys.readouterr().out
    kept = sum(1 for m in messages if m.chunk <= 9)
    assert f'{kept} messages kept' in out and '/pentapod/tcp_state' in out
    assert len(read_back(tmp_path / 'fixed')) == kept


def test_a_single_file_and_an_unchunked_file(tmp_path):
    from mcap.writer import Writer

    from fixtures.cdr import encode_clock
    file = tmp_path / 'loose.mcap'
    with open(file, 'wb') as stream:
        writer = Writer(stream, use_chunking=False)
        writer.start(profile='ros2')
        schema = writer.register_schema('rosgraph_msgs/msg/Clock', 'ros2msg',
                                        b'builtin_interfaces/Time clock\n')
        channel = writer.register_channel('/clock', 'cdr', schema)
        for k in range(50):
            writer.add_message(channel, k * 1000, encode_clock(k * 1000), k * 1000 + 1, k)
        writer.finish()
    data = file.read_bytes()
    cut = file.with_name('cut.mcap')
    cut.write_bytes(data[:len(data) // 2])
    recovery = recover_bag(cut)
    assert recovery.output == tmp_path / 'cut-recovered'
    got = _mcap_rows(recovery.output)
    assert 10 < len(got) < 50
    assert got == [('/clock', k * 1000, encode_clock(k * 1000), k * 1000 + 1, k)
                   for k in range(len(got))]
    shutil.rmtree(recovery.output)


def _status_bag(path, steps: int, statuses: dict) -> None:
    """tcp_state and /clock for ``steps`` steps of 1 ms; run status messages after some steps."""
    from rosbags.typesys import get_typestore, Stores

    from fixtures.cdr import encode_clock, encode_joint_state
    from pentapod_sim.recording import BagWriter
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    status_type = 'diagnostic_msgs/msg/DiagnosticStatus'
    with BagWriter(path, chunk_size=2048, flush_period_s=0.0) as writer:
        writer.add_topic(TOPICS[0], 'sensor_msgs/msg/JointState')
        writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
        writer.add_topic('/pentapod/run_status', status_type)
        for k in range(steps + 1):
            if k in statuses:
                state, n = statuses[k]
                values = {'state': state, 'steps': n, 'dt': 0.001,
                          'last_stamp_ns': (n - 1) * 1_000_000,
                          'step_topics': f'/clock,{TOPICS[0]}'}
                msg = T[status_type](0, 'plant', state, '', [T['diagnostic_msgs/msg/KeyValue'](
                    key, str(v)) for key, v in values.items()])
                writer.write('/pentapod/run_status', store.serialize_cdr(msg, status_type),
                             k * 1_000_000)
            if k < steps:
                writer.write(TOPICS[0], encode_joint_state(k * 1_000_000, ['tcp_x'], [k * 1e-6]),
                             k * 1_000_000)
                writer.write('/clock', encode_clock(k * 1_000_000), k * 1_000_000)


def test_the_run_status_in_the_bag_tells_the_missing_steps(tmp_path):
    """A killed recorder: the last status was 'running'; a chunk in the middle is damaged."""
    _status_bag(tmp_path / 'ref', 300, {0: ('running', 0), 200: ('running', 200),
                                        300: ('finished', 300)})
    file = tmp_path / 'ref' / 'ref_0.mcap'
    chunks, (messages, ends) = chunk_table(file), message_layout(file)
    last = max(m.chunk for m in messages if m.topic == '/pentapod/run_status' and m.log_time
               == 200_000_000)
    damaged = bytearray(file.read_bytes()[:ends[last + 2]])          # no 'finished' status
    damaged[(chunks[5].start + chunks[5].end) // 2] ^= 0x01
    bag = tmp_path / 'run'
    bag.mkdir()
    (bag / 'run_0.mcap').write_bytes(bytes(damaged))
    kept_steps = sorted(m.log_time // 1_000_000 for m in messages
                        if m.topic == TOPICS[0] and m.chunk != 5 and m.chunk <= last + 2)
    lost = sorted(set(range(300)) - set(kept_steps))
    inner = [k for k in lost if k < 200]
    assert inner and inner == list(range(inner[0], inner[-1] + 1))  # chunk 5: one run

    recovery = recover_bag(bag)
    assert (recovery.run.state, recovery.expected_steps, recovery.steps_exact) == \
        ('running', 200, False)
    steps = recovery.topics[TOPICS[0]].steps
    assert (steps.missing, steps.exact) == (len(inner), False)
    assert [g[:2] for g in steps.gaps] == [(inner[0], inner[-1])]
    assert steps.gaps[0][2:] == pytest.approx((inner[0] * 1e-3, inner[-1] * 1e-3), abs=1e-12)
    assert f'at least {len(inner)} missing: {inner[0]}-{inner[-1]}' in recovery.describe()

    given = recover_bag(bag, tmp_path / 'given', expected_steps=300)
    steps = given.topics[TOPICS[0]].steps
    assert (steps.missing, steps.exact) == (len(lost), True)
    assert [g[:2] for g in steps.gaps] == [(inner[0], inner[-1]), (lost[len(inner)], 299)]
    record = _records(tmp_path / 'given')[RECOVERY_RECORD]
    assert record['expected_steps'] == '300'
    clock = 300 - sum(1 for m in messages if m.topic == '/clock' and m.chunk != 5
                      and m.chunk <= last + 2)
    assert record['missing_steps'] == f'{{{TOPICS[0]}: {len(lost)}, /clock: {clock}}}'


def test_a_finished_run_status_gives_exact_counts(tmp_path):
    _status_bag(tmp_path / 'ref', 150, {0: ('running', 0), 150: ('finished', 150)})
    file = tmp_path / 'ref' / 'ref_0.mcap'
    messages, ends = message_layout(file)
    bag = tmp_path / 'run'
    bag.mkdir()
    (bag / 'run_0.mcap').write_bytes(file.read_bytes()[:ends[-1]])    # killed while closing
    recovery = recover_bag(bag)
    assert (recovery.expected_steps, recovery.steps_exact) == (150, True)
    for topic in (TOPICS[0], '/clock'):
        assert recovery.topics[topic].steps.describe() == 'steps 150, none missing'


def _records(folder) -> dict:
    with open(next(folder.glob('*.mcap')), 'rb') as stream:
        return {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
