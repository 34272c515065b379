"""
CDR (little endian, XCDR1) encoders for the few message types the testbed records.

They let ROS-free tools (offline runs, benchmarks, tests) write bags that rclpy, rosbags and
mcap_ros2 read. Hand-written because the only generic encoders need either a running ROS type
support (rclpy) or a per-message dict walk (mcap_ros2, about 10x slower); the layout is checked
against ``rclpy.serialization.serialize_message`` in test/test_recording.py.

Alignment follows Fast-CDR: offsets count from the end of the 4-byte encapsulation header, a
primitive of size s starts at a multiple of s, and an empty sequence adds no alignment padding
for its (absent) elements.
"""
import struct
from typing import Sequence

ENCAPSULATION_CDR_LE = b'\x00\x01\x00\x00'


class _CdrBuffer:
    """Append-only CDR body (without the encapsulation header)."""

    def __init__(self) -> None:
        self.parts = bytearray()

    def align(self, size: int) -> None:
        pad = (-len(self.parts)) % size
        self.parts += b'\x00' * pad

    def uint32(self, value: int) -> None:
        self.align(4)
        self.parts += struct.pack('<I', value)

    def int32(self, value: int) -> None:
        self.align(4)
        self.parts += struct.pack('<i', value)

    def string(self, text: str) -> None:
        raw = text.encode('utf-8') + b'\x00'
        self.uint32(len(raw))
        self.parts += raw

    def float64s(self, values: Sequence[float]) -> None:
        if len(values):
            self.align(8)
            self.parts += struct.pack(f'<{len(values)}d', *values)

    def float64_sequence(self, values: Sequence[float]) -> None:
        self.uint32(len(values))
        self.float64s(values)

    def stamp(self, stamp_ns: int) -> None:
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        self.int32(sec)
        self.uint32(nanosec)

    def message(self) -> bytes:
        return ENCAPSULATION_CDR_LE + bytes(self.parts)


def encode_joint_state(stamp_ns: int, names: Sequence[str], position: Sequence[float] = (),
                       velocity: Sequence[float] = (), effort: Sequence[float] = (),
                       frame_id: str = '') -> bytes:
    """
    Serialise a sensor_msgs/msg/JointState.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns] (sim time of the step).
    names : sequence of str
        Joint (channel) names.
    position, velocity, effort : sequence of float
        Values in SI units (m or rad, m/s or rad/s, N or N m); each empty or len(names) long.
    frame_id : str
        Header frame id.

    Returns
    -------
    bytes
        CDR message including the encapsulation header.
    """
    buf = _CdrBuffer()
    buf.stamp(stamp_ns)
    buf.string(frame_id)
    buf.uint32(len(names))
    for name in names:
        buf.string(name)
    for values in (position, velocity, effort):
        buf.float64_sequence(values)
    return buf.message()


def encode_wrench_stamped(stamp_ns: int, force: Sequence[float],
                          torque: Sequence[float] = (0.0, 0.0, 0.0),
                          frame_id: str = '') -> bytes:
    """
    Serialise a geometry_msgs/msg/WrenchStamped.

    Parameters
    ----------
    stamp_ns : int
        Header stamp [ns].
    force : sequence of 3 float
        Force [N].
    torque : sequence of 3 float
        Torque [N m].
    frame_id : str
        Header frame id.

    Returns
    -------
    bytes
        CDR message including the encapsulation header.
    """
    buf = _CdrBuffer()
    buf.stamp(stamp_ns)
    buf.string(frame_id)
    buf.float64s(list(force) + list(torque))
    return buf.message()


def encode_clock(stamp_ns: int) -> bytes:
    """
    Serialise a rosgraph_msgs/msg/Clock.

    Parameters
    ----------
    stamp_ns : int
        Simulation time [ns].

    Returns
    -------
    bytes
        CDR message including the encapsulation header.
    """
    buf = _CdrBuffer()
    buf.stamp(stamp_ns)
    return buf.message()
