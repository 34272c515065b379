"""
One writer per topic (pentapod_sim.nodes.writers).

The rule on a scripted graph, then real spoofers on the session's domain.
"""
from types import SimpleNamespace

import pytest

from pentapod_sim.errors import RunError
from pentapod_sim.nodes import writers
from pentapod_sim.nodes.writers import WriterCheck

TOPIC = '/pentapod/tcp_state'


def gid(host: int, pid: int, entity: int = 3) -> bytes:
    """A Fast DDS endpoint GUID: vendor 01.0f, host id, process id, ..., entity id."""
    return (b'\x01\x0f' + host.to_bytes(2, 'big') + pid.to_bytes(2, 'little') + bytes(6)
            + entity.to_bytes(4, 'big'))


def info(g: bytes, name: str = 'plant'):
    return SimpleNamespace(endpoint_gid=list(g), node_name=name, node_namespace='/')


class Graph:
    """A node whose graph shows ``self.pubs[topic]``; a subscription with a matched count."""

    def __init__(self):
        self.pubs: dict[str, list] = {}

    def get_publishers_info_by_topic(self, topic):
        return self.pubs.get(topic, [])


def test_a_second_writer_is_refused_naming_both_participants_and_hosts():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(0x78fd, 29691))]
    assert [w.gid for w in check.check()[TOPIC]] == [gid(0x78fd, 29691)]
    # the spoofer claims the plant's node name: it is told apart by its GUID
    graph.pubs[TOPIC].append(info(gid(0x78fd, 4242)))
    with pytest.raises(RunError) as err:
        check.check()
    text = str(err.value)
    assert f'{TOPIC} has 2 writers' in text
    assert 'process id 29691' in text and 'process id 4242' in text, text
    assert text.count('host id 78fd') == 2 and text.count('node /plant') == 2


def test_a_writer_that_replaced_the_pinned_one_is_refused():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(1, 10))]
    check.check()
    graph.pubs[TOPIC] = [info(gid(1, 11))]
    with pytest.raises(RunError, match='its writer changed between two checks'):
        check.check()


def test_shared_topics_allow_several_writers_and_record_them():
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC, shared=True)
    graph.pubs[TOPIC] = [info(gid(1, 10)), info(gid(1, 11))]
    assert len(check.check()[TOPIC]) == 2
    assert check.foreign() == {}


def test_messages_are_refused_while_dds_matched_a_second_writer(monkeypatch):
    """Per message: two matched publishers refuse every message; the graph check then stops."""
    now = [0.0]
    monkeypatch.setattr(writers.time, 'monotonic', lambda: now[0])
    graph = Graph()
    check = WriterCheck(graph)
    check.watch(TOPIC)
    graph.pubs[TOPIC] = [info(gid(1, 10))]
    check.check()
    sub = SimpleNamespace(count=1, get_publisher_count=lambda: sub.count)
    assert check.message_ok(TOPIC, sub)
    sub.count = 2                        # matched by DDS, not yet in the ROS graph
    assert not check.message_ok(TOPIC, sub) and not check.message_ok(TOPIC, sub)
    assert check.due()
    check.check()                        # within GRAPH_LAG: not yet stopped
    now[0] += writers.GRAPH_LAG + 0.01
    with pytest.raises(RunError, match=r'DDS matched a second writer \(2 message\(s\) refused'):
        check.check()
