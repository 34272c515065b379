"""
Bag integrity: checked CRCs and record lengths, damage reported and skipped, mcap fallback.

Never a traceback or a giant allocation; the fast reader falls back to mcap.reader (with one
warning) if the mcap internals it uses change.
"""
import shutil
import struct
import sys
import tracemalloc
from types import SimpleNamespace
import warnings

import mcap.opcode
from mcap.writer import CompressionType, Writer
import numpy as np
from numpy.testing import assert_array_equal
import pytest

from fixtures.bags import (
    chunk_table,
    CLOCK,
    N_STEPS,
    recorded,
    returned_messages,
    STATE,
    write_bag,
)
from fixtures.cdr import encode_clock
from pentapod_sim.analysis.bag import reader as bag_reader
from pentapod_sim.analysis.bag.file_content import BagDamageWarning, McapInternalsWarning
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.cli import analyze
from pentapod_sim.errors import BagError

TOTAL = 3 * N_STEPS


@pytest.fixture(scope='module')
def intact(tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'intact'
    values = recorded()
    write_bag(path, values)
    file = path / 'intact_0.mcap'
    return path, file.read_bytes(), chunk_table(file), values


def _copy(intact, tmp_path, data: bytes, name: str = 'damaged'):
    """A bag folder with the intact metadata.yaml and the given MCAP bytes."""
    folder = tmp_path / name
    folder.mkdir()
    shutil.copy(intact[0] / 'metadata.yaml', folder)
    (folder / 'intact_0.mcap').write_bytes(data)
    return folder


def _open_quietly(path, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        bag = open_bag(path, **kwargs)
    return bag, caught


def test_intact_bag_is_read_by_the_fast_reader_without_warnings(intact):
    path, _, _, values = intact
    bag, caught = _open_quietly(path)
    assert bag.reader == 'fast' and bag.damage == [] and caught == []
    assert returned_messages(bag, values) == TOTAL


def test_flipped_bit_in_a_chunk_skips_that_chunk_and_names_its_loss(intact, tmp_path):
    path, data, chunks, values = intact
    chunk = chunks[len(chunks) // 2]
    damaged = bytearray(data)
    damaged[(chunk.start + chunk.end) // 2] ^= 0x10  # inside its message records
    bag, caught = _open_quietly(_copy(intact, tmp_path, bytes(damaged)))
    [damage] = bag.damage
    assert damage.offset == chunk.start and 'CRC' in damage.reason
    assert damage.lost == chunk.counts and set(damage.topics) == set(chunk.counts)
    assert (damage.start_ns, damage.end_ns) == (chunk.start_ns, chunk.end_ns)
    assert returned_messages(bag, values) == TOTAL - chunk.n
    [warning] = caught
    assert warning.category is BagDamageWarning and f'{chunk.n} messages lost' in str(
        warning.message)


def test_fifty_flipped_bytes_mid_file_lose_only_their_chunks(intact, tmp_path):
    """The issue's reproduction (it ended in OverflowError): now a report and the rest."""
    _, data, chunks, values = intact
    rng = np.random.default_rng(50)
    damaged = bytearray(data)
    middle = len(data) // 2
    hit = rng.choice(np.arange(middle - 400, middle + 400), size=50, replace=False)
    for position in hit:
        damaged[position] ^= 0xFF
    tracemalloc.start()
    bag, _ = _open_quietly(_copy(intact, tmp_path, bytes(damaged)))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 << 20
    spoiled = [c for c in chunks if any(c.start <= h < c.end for h in hit)]
    assert returned_messages(bag, values) == TOTAL - sum(c.n for c in spoiled)
    assert sum(d.messages_lost for d in bag.damage) == sum(c.n for c in spoiled)


def _unchecked_bag(tmp_path) -> tuple:
    """An MCAP without CRCs (some writers omit them): only lengths guard its chunks."""
    file = tmp_path / 'nocrc.mcap'
    with open(file, 'wb') as stream:
        writer = Writer(stream, chunk_size=1024, compression=CompressionType.NONE,
                        enable_crcs=False)
        writer.start(profile='ros2')
        schema = writer.register_schema('rosgraph_msgs/msg/Clock', 'ros2msg',
                                        b'builtin_interfaces/Time clock')
        channel = writer.register_channel(CLOCK, 'cdr', schema)
        for k in range(200):
            writer.add_message(channel, k, encode_clock(k), k)
        writer.finish()
    return file, chunk_table(file)


def test_record_length_past_the_chunk_end_is_reported_not_allocated(tmp_path):
    file, chunks = _unchecked_bag(tmp_path)
    data = bytearray(file.read_bytes())
    chunk = chunks[1]
    # the first message record of the chunk: after 9 + 8 + 8 + 8 + 4 + 4 + 8 header bytes
    first_record = chunk.start + 9 + 40
    assert data[first_record] == mcap.opcode.Opcode.MESSAGE
    data[first_record + 1:first_record + 9] = struct.pack('<Q', 2 ** 63 - 1)
    file.write_bytes(bytes(data))
    tracemalloc.start()
    bag, _ = _open_quietly(file)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 << 20
    [damage] = bag.damage
    assert 'runs past the chunk end' in damage.reason and damage.lost == {CLOCK: chunk.n}
    assert_array_equal(bag.series(f'{CLOCK}.clock').time_ns,
                       [k for k in range(200) if not chunk.start_ns <= k <= chunk.end_ns])


def test_cut_file_with_a_huge_chunk_length_keeps_what_precedes(intact, tmp_path):
    """No footer (a crash) and a damaged length: the sequential read stops there, reported."""
    _, data, chunks, values = intact
    chunk = chunks[3]
    damaged = bytearray(data[:chunks[6].start + 10])
    damaged[chunk.start + 1:chunk.start + 9] = struct.pack('<Q', 2 ** 64 - 2)
    bag, caught = _open_quietly(_copy(intact, tmp_path, bytes(damaged)))
    assert bag.truncated and 'ends early' in str(caught[0].message)
    assert returned_messages(bag, values) == sum(c.n for c in chunks[:3])
    assert sum(d.messages_lost for d in bag.damage) == TOTAL - sum(c.n for c in chunks[:3])


def test_cut_file_with_a_damaged_chunk_skips_it_and_reads_on(intact, tmp_path):
    """Sequential read (no footer): the damaged chunk's loss comes from its Message Index."""
    _, data, chunks, values = intact
    damaged = bytearray(data[:chunks[6].start + 10])
    damaged[(chunks[2].start + chunks[2].end) // 2] ^= 0x80
    bag, _ = _open_quietly(_copy(intact, tmp_path, bytes(damaged)))
    skipped, cut = bag.damage
    assert skipped.offset == chunks[2].start and skipped.lost == chunks[2].counts
    assert (skipped.start_ns, skipped.end_ns) == (chunks[2].start_ns, chunks[2].end_ns)
    kept = sum(c.n for c in chunks[:6]) - chunks[2].n
    assert returned_messages(bag, values) == kept
    assert cut.offset == chunks[6].start and cut.messages_lost == TOTAL - kept - chunks[2].n


def test_cut_inside_a_chunk_reports_its_time_span_and_loss(intact, tmp_path):
    _, data, chunks, values = intact
    chunk = chunks[4]
    bag, caught = _open_quietly(_copy(intact, tmp_path, data[:chunk.start + 100]))
    [damage] = bag.damage
    assert bag.truncated and 'ends early' in str(caught[0].message)
    assert (damage.start_ns, damage.end_ns) == (chunk.start_ns, chunk.end_ns)
    kept = sum(c.n for c in chunks[:4])
    assert returned_messages(bag, values) == kept
    assert damage.messages_lost == TOTAL - kept  # from metadata.yaml's counts


def test_damaged_summary_is_reported_and_the_data_section_read_in_full(intact, tmp_path):
    _, data, chunks, values = intact
    damaged = bytearray(data)
    damaged[chunks[-1].end + (len(data) - chunks[-1].end) // 2] ^= 0x01
    bag, _ = _open_quietly(_copy(intact, tmp_path, bytes(damaged)))
    [damage] = bag.damage
    assert 'summary' in damage.reason and damage.lost == {}
    assert returned_messages(bag, values) == TOTAL and not bag.truncated


def test_unchunked_file_is_read_record_by_record(tmp_path):
    file = tmp_path / 'flat.mcap'
    with open(file, 'wb') as stream:
        writer = Writer(stream, use_chunking=False)
        writer.start(profile='ros2')
        schema = writer.register_schema('rosgraph_msgs/msg/Clock', 'ros2msg', b'x')
        channel = writer.register_channel(CLOCK, 'cdr', schema)
        for k in range(50):
            writer.add_message(channel, 7 * k, encode_clock(3 * k), 7 * k)
        writer.finish()
    bag, caught = _open_quietly(file)
    assert caught == [] and bag.damage == []
    assert_array_equal(bag.series(f'{CLOCK}.clock').time_ns, 3 * np.arange(50))
    assert_array_equal(bag.topics[CLOCK].log_time_ns, 7 * np.arange(50))


def test_message_shorter_than_its_type_is_a_bag_error(tmp_path):
    file = tmp_path / 'short.mcap'
    with open(file, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2')
        schema = writer.register_schema('rosgraph_msgs/msg/Clock', 'ros2msg', b'x')
        channel = writer.register_channel(CLOCK, 'cdr', schema)
        writer.add_message(channel, 0, encode_clock(0), 0)
        writer.add_message(channel, 1, b'\x00\x01\x00\x00\x05', 1)  # 5 of 12 bytes
        writer.finish()
    with pytest.raises(BagError, match='message 1 has 5 bytes'):
        open_bag(file).series(f'{CLOCK}.clock')


def test_analyze_info_prints_the_damage_and_exits_0(intact, tmp_path, capsys):
    _, data, chunks, _ = intact
    damaged = bytearray(data)
    damaged[(chunks[2].start + chunks[2].end) // 2] ^= 0x04
    folder = _copy(intact, tmp_path, bytes(damaged))
    assert analyze.main(['info', str(folder)]) == 0
    out, err = capsys.readouterr()
    assert f'DAMAGE: 1 damaged or missing part(s), {chunks[2].n} messages lost' in out
    assert f'{N_STEPS - chunks[2].counts[STATE]:9d} msgs' in out
    assert 'Traceback' not in out + err and 'BagDamageWarning' not in err


def test_analyze_info_exits_1_when_nothing_is_readable(intact, tmp_path, capsys):
    _, data, chunks, _ = intact
    folder = _copy(intact, tmp_path, data[:chunks[0].end - 5])
    assert analyze.main(['info', str(folder)]) == 1
    out, err = capsys.readouterr()
    assert 'nothing readable' in err and 'Traceback' not in out + err


def _equal_bags(first, second) -> None:
    assert set(first.topics) == set(second.topics)
    for name, data in first.topics.items():
        other = second.topics[name]
        assert [bytes(p) for p in data.payloads] == [bytes(p) for p in other.payloads]
        assert_array_equal(data.log_time_ns, other.log_time_ns)
        assert data.msg_type == other.msg_type and data.schema_text == other.schema_text
    assert first.custom_data == second.custom_data


@pytest.mark.parametrize('break_internals', ['import', 'attribute'])
def test_changed_mcap_internals_fall_back_to_mcap_reader_with_one_warning(
        intact, monkeypatch, break_internals):
    path, _, _, values = intact
    fast, _ = _open_quietly(path)
    monkeypatch.setitem(bag_reader.FALLBACK, 'reason', None)
    if break_internals == 'import':
        monkeypatch.setitem(sys.modules, 'mcap.data_stream', None)  # the module is gone
    else:  # an opcode renamed in a new release: an AttributeError where it is used
        members = dict(mcap.opcode.Opcode.__members__)
        members.pop('CHUNK_INDEX')
        monkeypatch.setattr(mcap.opcode, 'Opcode', SimpleNamespace(**members))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        first = open_bag(path)
        second = open_bag(path, topics=[STATE])
    assert [w.category for w in caught] == [McapInternalsWarning]
    assert first.reader == second.reader == 'mcap.reader'
    assert first.damage == [] and fast.reader == 'fast'
    _equal_bags(fast, first)
    assert returned_messages(first, values) == TOTAL
    assert second.topics[STATE].count == N_STEPS and second.topics[CLOCK].count == 0


def test_public_reader_is_selectable_and_agrees(intact):
    path, _, _, _ = intact
    fast, _ = _open_quietly(path)
    public, caught = _open_quietly(path, reader='mcap.reader')
    assert public.reader == 'mcap.reader' and caught == []
    _equal_bags(fast, public)
    with pytest.raises(BagError, match='unknown bag reader'):
        open_bag(path, reader='slow')

