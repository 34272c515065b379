"""
CDR bytes of rclpy message objects, as a DDS subscriber takes them (raw) off the wire.

A recorder in a composition gets the per-step messages as objects
(:mod:`pentapod_sim.nodes.local_bus`) and must write the bytes a recorder in another process
gets. ``rclpy.serialization.serialize_message`` does not give them: rmw_fastrtps sizes its buffer
by an estimate (up to 8 bytes too long, the tail uninitialised memory) and leaves alignment
padding unwritten (garbage), while the DDS sample holds exactly the serialised length with
zeroed padding, the whole padded with zeros to a multiple of 4 bytes (little-endian XCDR1,
encapsulation header ``00 01 00 00``). rosbags' CDR serialiser writes those bytes but costs
several times more per message; the recorder pays it per step, so the per-step types of a run,
sensor_msgs/JointState, rosgraph_msgs/Clock and geometry_msgs/WrenchStamped (excitation), have
direct serialisers here (:class:`JointStateCdr`, :func:`clock_cdr`, :class:`WrenchStampedCdr`:
the same layout written with ``struct``, the header and names block cached per name list;
bench/bench_wire_cdr.py measures them against rosbags').
Other types have none (:func:`serializer` gives None) and stay on DDS.
test/test_wire_cdr.py checks the direct serialisers against rosbags' serialiser
(test/fixtures/rosbags_cdr.py), test/test_composed_handoff.py against a DDS recorder's bag.
"""
from __future__ import annotations

import array
import struct
import sys


def type_name(cls) -> str:
    """``pkg/msg/Type`` of an rclpy message class."""
    return f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'


#: CDR encapsulation header: little-endian plain CDR, no options.
ENCAPSULATION = b'\x00\x01\x00\x00'
_STAMP = struct.Struct('<iI')
_COUNT = struct.Struct('<I')


class JointStateCdr:
    """Wire CDR of sensor_msgs/JointState (little-endian machine)."""

    MAX_BLOCKS = 64     # distinct (frame_id, names) kept

    def __init__(self):
        self._blocks: dict[tuple, bytes] = {}

    def __call__(self, msg) -> bytes:
        header = msg.header
        key = (header.frame_id, tuple(msg.name))
        block = self._blocks.get(key)
        if block is None:
            if len(self._blocks) >= self.MAX_BLOCKS:
                self._blocks.clear()
            block = self._blocks[key] = _strings_block(*key)
        parts = [ENCAPSULATION, _STAMP.pack(header.stamp.sec, header.stamp.nanosec), block]
        size = 8 + len(block)                       # body bytes so far (alignment origin)
        for values in (msg.position, msg.velocity, msg.effort):
            pad = -size % 4
            parts.append(bytes(pad) + _COUNT.pack(len(values)))
            size += pad + 4
            if len(values):
                data = (values if isinstance(values, array.array)
                        else array.array('d', values)).tobytes()
                pad = -size % 8
                parts.append(bytes(pad) + data)
                size += pad + len(data)
        parts.append(bytes(-size % 4))              # DDS pads the sample to 4 bytes
        return b''.join(parts)


def _strings_block(frame_id: str, names: tuple) -> bytes:
    """The frame_id and name fields of a JointState (they start at body offset 8)."""
    out = bytearray()

    def string(text: str) -> None:
        data = text.encode()
        out.extend(_COUNT.pack(len(data) + 1) + data + b'\x00')

    string(frame_id)
    out.extend(bytes(-(8 + len(out)) % 4))
    out.extend(_COUNT.pack(len(names)))
    for name in names:
        out.extend(bytes(-(8 + len(out)) % 4))
        string(name)
    return bytes(out)


_WRENCH = struct.Struct('<6d')


class WrenchStampedCdr:
    """Wire CDR of geometry_msgs/WrenchStamped (little-endian machine)."""

    def __init__(self):
        self._frames: dict[str, bytes] = {}

    def __call__(self, msg) -> bytes:
        header, wrench = msg.header, msg.wrench
        frame = self._frames.get(header.frame_id)
        if frame is None:
            if len(self._frames) >= JointStateCdr.MAX_BLOCKS:
                self._frames.clear()
            data = header.frame_id.encode()
            frame = _COUNT.pack(len(data) + 1) + data + b'\x00'
            frame += bytes(-(8 + len(frame)) % 8)       # the wrench's doubles align to 8
            self._frames[header.frame_id] = frame
        force, torque = wrench.force, wrench.torque
        return b''.join((ENCAPSULATION, _STAMP.pack(header.stamp.sec, header.stamp.nanosec),
                         frame, _WRENCH.pack(force.x, force.y, force.z,
                                             torque.x, torque.y, torque.z)))


def clock_cdr(msg) -> bytes:
    """Wire CDR of rosgraph_msgs/Clock."""
    return ENCAPSULATION + _STAMP.pack(msg.clock.sec, msg.clock.nanosec)


#: Types with a direct path: type name -> factory of the serialiser.
DIRECT = {'sensor_msgs/msg/JointState': JointStateCdr,
          'rosgraph_msgs/msg/Clock': lambda: clock_cdr,
          'geometry_msgs/msg/WrenchStamped': WrenchStampedCdr}




def serializer(cls):
    """
    The wire CDR serialiser of an rclpy message class, or None if it has no direct path.

    A composition's recorder takes from the local bus only the topics whose type has one; the
    others stay on DDS.
    """
    if sys.byteorder != 'little':
        return None
    factory = DIRECT.get(type_name(cls))
    return factory() if factory is not None else None
