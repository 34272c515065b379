"""
CDR bytes of rclpy message objects, as a DDS subscriber takes them (raw) off the wire.

A recorder in a composition gets the per-step messages as objects
(:mod:`pentapod_sim.nodes.local_bus`) and must write the bytes a recorder in another process
gets. ``rclpy.serialization.serialize_message`` does not give them: rmw_fastrtps sizes its buffer
by an estimate (up to 8 bytes too long, the tail uninitialised memory) and leaves alignment
padding unwritten (garbage), while the DDS sample holds exactly the serialised length with
zeroed padding, the whole padded with zeros to a multiple of 4 bytes. rosbags' CDR serialiser
writes the same (little-endian XCDR1, encapsulation header ``00 01 00 00``, zero padding);
:class:`WireCdr` converts an rclpy object to the rosbags message class of its type,
serialises it and pads the end.

The per-step types of a run, sensor_msgs/JointState and rosgraph_msgs/Clock, take a direct path
(:class:`JointStateCdr`, :func:`clock_cdr`; hand-written because the recorder pays it per
step: bench/bench_wire_cdr.py measures it against rosbags' serialiser): the same layout
written with ``struct``, the header and names block cached per name list.
test/test_wire_cdr.py checks them against rosbags' serialiser, test/test_composed_handoff.py
against a DDS recorder's bag.
"""
from __future__ import annotations

import array
import functools
import importlib
import struct
import sys

import numpy as np


def type_name(cls) -> str:
    """``pkg/msg/Type`` of an rclpy message class."""
    return f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'


@functools.cache
def typestore():
    """The ROS 2 Jazzy type store of rosbags (built once; imported only when needed)."""
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


class WireCdr:
    """
    Serialiser of one rclpy message class to wire CDR bytes.

    Parameters
    ----------
    cls : type
        The rclpy message class.
    direct : bool
        Use the direct path of the type if it has one (:data:`DIRECT`); False: rosbags.

    Raises
    ------
    KeyError
        If rosbags' Jazzy type store lacks the type (or a nested one).
    """

    def __init__(self, cls, direct: bool = True):
        self.name = type_name(cls)
        fast = DIRECT.get(self.name) if direct and sys.byteorder == 'little' else None
        self._direct = fast() if fast is not None else None
        if self._direct is None:
            self._store = typestore()
            self._convert = _converter(cls, self._store)

    def __call__(self, msg) -> bytes:
        """The CDR bytes (with encapsulation header) of ``msg``."""
        if self._direct is not None:
            return self._direct(msg)
        data = self._store.serialize_cdr(self._convert(msg), self.name).tobytes()
        return data + bytes(-len(data) % 4)


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


def clock_cdr(msg) -> bytes:
    """Wire CDR of rosgraph_msgs/Clock."""
    return ENCAPSULATION + _STAMP.pack(msg.clock.sec, msg.clock.nanosec)


#: Types with a direct path: type name -> factory of the serialiser.
DIRECT = {'sensor_msgs/msg/JointState': JointStateCdr,
          'rosgraph_msgs/msg/Clock': lambda: clock_cdr}


def _converter(cls, store):
    """A function building the rosbags object of an rclpy message of ``cls``."""
    target = store.types[type_name(cls)]
    fields = []
    for field, ftype in cls.get_fields_and_field_types().items():
        sample = getattr(cls(), field)
        if hasattr(sample, 'get_fields_and_field_types'):
            fields.append((field, _converter(type(sample), store)))
        elif isinstance(sample, array.array):
            fields.append((field, _numbers))
        elif ftype == 'octet':
            fields.append((field, ord))
        elif ftype.startswith('sequence<') and '/' in ftype:
            inner = _converter(_nested_class(ftype), store)
            fields.append((field, lambda items, inner=inner: [inner(i) for i in items]))
        else:
            fields.append((field, None))

    def convert(msg):
        values = {}
        for field, conv in fields:
            value = getattr(msg, field)
            values[field] = value if conv is None else conv(value)
        return target(**values)
    return convert


def _numbers(values: array.array) -> np.ndarray:
    return np.frombuffer(values, dtype=values.typecode)


def _nested_class(ftype: str):
    pkg, name = ftype[len('sequence<'):].rstrip('>').split(',')[0].split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)
