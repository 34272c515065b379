"""
The excitation a recorded run used, read back from its bag (ROS-free).

An exciter publishes the parameters of its signal once per run on
``/pentapod/excitation_spec/<source>`` (std_msgs/String, transient local; see
:data:`pentapod_sim.interface.EXCITATION_SPEC_PREFIX`), and the recorder stores that message.
:func:`excitation_of` returns the :class:`~pentapod_sim.sim.excitation.ExcitationSpec` and the
plant sample time, so the analysis can rebuild the exact signal
(``Excitation(spec, dt)``: period, lines, stepped-sine windows) without the user passing them
again.
"""
from __future__ import annotations

from pathlib import Path
import struct

from pentapod_sim.analysis.bag.reader import Bag, open_bag
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.interface import EXCITATION_SPEC_PREFIX, excitation_spec_topic
from pentapod_sim.sim.excitation_spec import check_spec, ExcitationSpec, parse_spec_message


def string_of(payload: bytes) -> str:
    """Text of one CDR-serialised std_msgs/String (either byte order)."""
    if len(payload) < 8 or payload[1] not in (0, 1):
        raise BagError(f'not a CDR std_msgs/String ({len(payload)} bytes)')
    order = '<' if payload[1] == 1 else '>'
    (length,) = struct.unpack_from(order + 'I', payload, 4)
    if length < 1 or 8 + length > len(payload):
        raise BagError(f'std_msgs/String of {len(payload)} bytes claims {length} characters')
    return bytes(payload[8:8 + length - 1]).decode('utf-8')


def _spec_topics(bag: Bag) -> list[str]:
    return sorted(t for t in bag.topics if t.startswith(EXCITATION_SPEC_PREFIX))


def excitations_of(bag: Bag | str | Path) -> dict[str, tuple[ExcitationSpec, float]]:
    """
    Every exciter's signal in a bag: ``{source: (spec, dt [s])}`` (empty if none was recorded).

    ``bag`` is an open :class:`~pentapod_sim.analysis.bag.reader.Bag` or a bag path (then only
    the excitation topics are loaded). The last message of each topic counts.

    Raises
    ------
    BagError
        If a message is not a valid excitation record (naming the topic and the fault).
    """
    if not isinstance(bag, Bag):
        topics = _spec_topics(open_bag(bag, topics=[]))
        if not topics:
            return {}
        bag = open_bag(bag, topics=topics)
    out = {}
    for topic in _spec_topics(bag):
        data = bag.topic(topic)
        if not data.count:
            continue
        try:
            spec, dt, source = parse_spec_message(string_of(data.payloads[data.count - 1]))
            check_spec(spec, dt)
        except (ConfigError, UnicodeDecodeError) as err:
            raise BagError(f'{topic} in {bag.path}: {err}') from None
        out[topic.removeprefix(EXCITATION_SPEC_PREFIX)] = (spec, dt)
    return out


def excitation_of(bag: Bag | str | Path,
                  source: str | None = None) -> tuple[ExcitationSpec, float] | None:
    """
    The excitation of a recorded run: (spec, plant sample time dt [s]), or None if absent.

    Parameters
    ----------
    bag : Bag, str or Path
        An open bag or a bag path.
    source : str, optional
        Name of the exciter (its ``source_name``); needed only if the bag holds several.

    Raises
    ------
    BagError
        If the bag holds several exciters and ``source`` is not given, or a record is bad.
    """
    if source is not None and not isinstance(bag, Bag):
        bag = open_bag(bag, topics=[excitation_spec_topic(source)])
    found = excitations_of(bag)
    if source is not None:
        return found.get(source)
    if len(found) > 1:
        raise BagError(f'{getattr(bag, "path", bag)} holds the excitation of several sources '
                       f'{sorted(found)}; name one')
    return next(iter(found.values()), None)
