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
"""
from __future__ import annotations

import array
import functools
import importlib

import numpy as np
from rosbags.typesys import get_typestore, Stores


def type_name(cls) -> str:
    """``pkg/msg/Type`` of an rclpy message class."""
    return f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'


@functools.cache
def typestore():
    """The ROS 2 Jazzy type store of rosbags (built once)."""
    return get_typestore(Stores.ROS2_JAZZY)


class WireCdr:
    """
    Serialiser of one rclpy message class to wire CDR bytes.

    Raises
    ------
    KeyError
        If rosbags' Jazzy type store lacks the type (or a nested one).
    """

    def __init__(self, cls):
        self.name = type_name(cls)
        self._store = typestore()
        self._convert = _converter(cls, self._store)

    def __call__(self, msg) -> bytes:
        """The CDR bytes (with encapsulation header) of ``msg``."""
        data = self._store.serialize_cdr(self._convert(msg), self.name).tobytes()
        return data + bytes(-len(data) % 4)


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
