"""
The live view's worker: topic streams in, Foxglove WebSocket channels out (ROS-free).

:class:`LiveHub` owns the foxglove-sdk WebSocket server and a worker thread. Every
``tick_period`` the worker calls the node's ``poll`` (which takes the raw CDR bytes its
subscriptions hold into the :class:`TopicStream` backlogs; the plant's state and force topics
arrive as its display batches, :class:`BatchStream`), decodes the backlogs, downsamples
them to min/max envelopes, updates the TCP spectrum and the run status (passing the plant's
run-status messages through, :meth:`LiveHub.add_run_status`) and logs the results on Foxglove
channels (serialising and computing spectra only for channels a client subscribed to) whose
schemas are
the ros2msg definitions of the message types and whose payloads are CDR, as a ROS 2 graph
would deliver them. Channel topics are the ROS topic names (plus the live-only channels of
:data:`pentapod_sim.interface.LIVE_PREFIX`), so one Foxglove layout works live and on bags.
Messages are serialised by an encoder the node passes in (rclpy), keeping this module ROS-free.
"""
from __future__ import annotations

from collections import deque
import logging
import os
from pathlib import Path
import threading
import time
from typing import Callable, Mapping, Protocol, Sequence

import foxglove
from foxglove.websocket import Capability, WebSocketServer
import numpy as np
import numpy.typing as npt

from pentapod_sim import interface
from pentapod_sim.errors import ConfigError
from pentapod_sim.live.envelope import Sample
from pentapod_sim.live.params import LiveViewParams
from pentapod_sim.live.spectrum import RunningSpectrum
from pentapod_sim.live.status import RunStatus, STATUS_NAMES
from pentapod_sim.live.streams import BatchStream, Shape, TopicStream
from pentapod_sim.recording.msgdefs import message_definition

LOGGER = logging.getLogger(__name__)
#: The TCP joints, in the plant's order (their spectrum channels are made at start).
TCP_JOINTS = tuple(dict.fromkeys(joint for topic, joint, _ in interface.PORT_LOCATION.values()
                                 if topic == interface.TCP_STATE))


def lower_priority(increment: int) -> int:
    """
    Add ``increment`` to the niceness of every thread of this process; return how many.

    Linux keeps a niceness per thread (``os.nice`` changes only the caller's), so each task of
    /proc/self/task is reniced: the DDS, foxglove-sdk and worker threads alike.
    """
    if increment <= 0:
        return 0
    tasks = Path('/proc/self/task')
    ids = [int(t) for t in os.listdir(tasks)] if tasks.is_dir() else [0]
    changed = 0
    for tid in ids:
        try:
            os.setpriority(os.PRIO_PROCESS, tid,
                           min(19, os.getpriority(os.PRIO_PROCESS, tid) + increment))
            changed += 1
        except OSError:      # the thread ended meanwhile
            pass
    return changed


class Encoder(Protocol):
    """Serialises the live view's messages (the node implements it with rclpy)."""

    def joint_state(self, stamp_ns: int, frame_id: str, names: Sequence[str],
                    fields: dict[str, list[float]]) -> bytes:
        """sensor_msgs/JointState."""

    def wrench(self, stamp_ns: int, frame_id: str, values: Sequence[float]) -> bytes:
        """geometry_msgs/WrenchStamped (force x, y, z, torque x, y, z)."""

    def float_array(self, label: str, values: Sequence[float]) -> bytes:
        """std_msgs/Float64MultiArray with one dimension called ``label``."""


class LiveHub:
    """
    Foxglove server, channels and worker thread of the live view.

    Parameters
    ----------
    params : LiveViewParams
        The node's parameters (:class:`pentapod_sim.live.params.LiveViewParams`).
    encoder : Encoder
        Message serialiser.
    clock : callable
        Wall clock [s] (monotonic).
    poll : callable
        Called by the worker at the start of every pass to fill the topic streams.
    """

    def __init__(self, params: LiveViewParams, encoder: Encoder,
                 clock: Callable[[], float] = time.monotonic,
                 poll: Callable[[], None] = lambda: None):
        self.p, self.encoder, self.clock, self.poll = params, encoder, clock, poll
        self._run_status: deque[tuple[bytes, dict[str, str]]] = deque()
        self.period_ns = max(1, int(round(1e9 / params.display_rate)))
        self.context = foxglove.Context()
        self.streams: dict[str, TopicStream] = {}
        self.channels: dict[str, foxglove.Channel] = {}
        self.status = RunStatus()
        self.spectrum = RunningSpectrum(params.spectrum_samples)
        self._spectrum_joints: list[str] = []
        self.server: WebSocketServer | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._arrival: dict[str, float] = {}
        self._next = {'status': 0.0, 'spectrum': 0.0}
        self._last_status: tuple[bytes, int] | None = None    # CDR bytes, log time [ns]
        self._status_watched = False
        self._channel(interface.LIVE_STATUS, interface.JOINT_STATE)
        self._channel(interface.RUN_STATUS, interface.DIAGNOSTIC_STATUS)
        for name in ('frequency',) + TCP_JOINTS:
            self._channel(interface.tcp_spectrum_topic(name), interface.FLOAT64_MULTI_ARRAY)

    # -- set-up (executor thread) ------------------------------------------------------------
    def _channel(self, topic: str, msg_type: str) -> foxglove.Channel:
        schema = foxglove.Schema(name=msg_type, encoding='ros2msg',
                                 data=message_definition(msg_type).encode('utf-8'))
        channel = foxglove.Channel(topic, message_encoding='cdr', schema=schema,
                                   context=self.context)
        self.channels[topic] = channel
        return channel

    def add_topic(self, topic: str, msg_type: str, batched: bool = False) -> TopicStream:
        """
        Serve a topic: make its stream and its Foxglove channel.

        ``batched``: the stream takes the plant's display batches of the topic
        (:class:`BatchStream`) instead of its per-step messages.
        """
        kind = BatchStream if batched else TopicStream
        stream = kind(topic, msg_type, self.period_ns, self.p.queue_depth)
        self._channel(topic, msg_type)
        self.streams[topic] = stream
        return stream

    def wanted(self, topic: str) -> bool:
        """
        True while a client watches ``topic``'s channel or a channel made from it.

        The run figures are made from the state topics' stamps, the spectrum from the TCP
        state (any thread).
        """
        channels = self.channels
        if channels[topic].has_sinks():
            return True
        if topic in interface.STATE_TOPICS and channels[interface.LIVE_STATUS].has_sinks():
            return True
        return topic == interface.TCP_STATE and any(
            channels[interface.tcp_spectrum_topic(name)].has_sinks()
            for name in ('frequency',) + TCP_JOINTS)

    def add_run_status(self, data: bytes, values: Mapping[str, str]) -> None:
        """
        Take one run-status message of the plant: its CDR bytes and key/value pairs.

        Any thread; the worker forwards the bytes as they are on the run-status channel and
        passes the figures into the live status at its next pass.
        """
        self._run_status.append((data, dict(values)))

    def start(self) -> int:
        """Start the WebSocket server and the worker; return the port it listens on."""
        try:
            server = foxglove.start_server(
                name='pentapod live view', host=self.p.host, port=self.p.port,
                capabilities=[Capability.Time], context=self.context)
        except Exception as err:   # the SDK raises RuntimeError for a taken port, bad host
            raise ConfigError(f'live view cannot listen on {self.p.host}:{self.p.port}: '
                              f'{err}') from None
        self._thread = threading.Thread(target=self._work, name='live_view_worker',
                                        daemon=True)
        self.server = server
        self._thread.start()
        return server.port

    def stop(self) -> None:
        """Stop the worker (after a last pass that sends every open window) and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        if self.server is not None:
            self.server.stop()
            self.server = None

    # -- worker thread -----------------------------------------------------------------------
    def _work(self) -> None:
        while not self._stop.wait(self.p.tick_period):
            self.tick(self.clock())
        self.tick(self.clock(), final=True)

    def tick(self, wall: float, final: bool = False) -> None:
        """One pass: every backlog, idle flushes, status and spectrum when due."""
        self.poll()
        channel = self.channels[interface.RUN_STATUS]
        watched, self._status_watched = self._status_watched, channel.has_sinks()
        while self._run_status:
            data, values = self._run_status.popleft()
            self.status.add_plant(values)
            self._last_status = (data, self._status_stamp(values))
            channel.log(data, log_time=self._last_status[1])
            watched = True          # a client watching now got it
        if self._status_watched and not watched and self._last_status is not None:
            # a client that started watching after the last status gets it too (the topic
            # is transient local, as foxglove_bridge hands a late subscriber the last one)
            channel.log(self._last_status[0], log_time=self._last_status[1])
        newest = -1
        for stream in list(self.streams.values()):
            self._pass(stream, wall, final)
            newest = max(newest, stream.last_stamp)
        if newest >= 0 and self.server is not None:
            self.server.broadcast_time(newest)
        if wall >= self._next['status'] or final:
            self._next['status'] = wall + self.p.status_period
            self._send_status(wall)
        if wall >= self._next['spectrum'] or final:
            self._next['spectrum'] = wall + self.p.spectrum_period
            self._send_spectrum()

    def _pass(self, stream: TopicStream, wall: float, final: bool) -> None:
        batch = stream.take()
        if batch:
            self._arrival[stream.topic] = wall
        for part in stream.process(batch):
            if part.new_run:
                self._new_run(stream.topic)
            self._send(stream, part.display)
            stamps, values = part.samples
            if stream.topic in interface.STATE_TOPICS:
                self.status.add(stamps)
            if stream.topic == interface.TCP_STATE and len(stamps) and stream.shape is not None:
                self._feed_spectrum(stream.shape, stamps, values)
        quiet = wall - self._arrival.get(stream.topic, wall) >= self.p.idle_flush
        if (quiet or final) and stream.envelope.pending:
            self._send(stream, stream.flush())

    def _new_run(self, topic: str) -> None:
        """Stamps of a plant output went back: a new run; reset the derived figures."""
        if topic in interface.STATE_TOPICS:
            LOGGER.info('%s: stamps went back, a new run started', topic)
            self.status.reset()
            self.spectrum.reset()

    def _send(self, stream: TopicStream, samples: Sequence[Sample]) -> None:
        channel, shape = self.channels[stream.topic], stream.shape or Shape()
        if not channel.has_sinks():
            return                # no client subscribed: nothing to serialise
        for stamp, row in samples:
            if stream.msg_type == interface.WRENCH_STAMPED:
                data = self.encoder.wrench(stamp, shape.frame_id, row.tolist())
            else:
                data = self.encoder.joint_state(stamp, shape.frame_id, shape.names,
                                                shape.split(row))
            channel.log(data, log_time=stamp)

    def _feed_spectrum(self, shape: Shape, stamps: npt.NDArray[np.int64],
                       values: npt.NDArray[np.float64]) -> None:
        field = self.p.spectrum_field
        start = 0
        for name, count in shape.fields:
            if name == field:
                cols = values[:, start:start + count]
                wanted = [shape.names.index(j) for j in TCP_JOINTS if j in shape.names]
                self.spectrum.add(stamps, cols[:, wanted])
                self._spectrum_joints = [shape.names[i] for i in wanted]
                return
            start += count

    def _send_spectrum(self) -> None:
        if not any(self.channels[interface.tcp_spectrum_topic(name)].has_sinks()
                   for name in ('frequency',) + TCP_JOINTS):
            return                # no client subscribed: nothing to compute
        result = self.spectrum.compute()
        if result is None:
            return
        freq, amplitude = result
        stamp = self.spectrum.newest
        self.channels[interface.tcp_spectrum_topic('frequency')].log(
            self.encoder.float_array('frequency', freq.tolist()), log_time=stamp)
        for k, joint in enumerate(self._spectrum_joints):
            self.channels[interface.tcp_spectrum_topic(joint)].log(
                self.encoder.float_array(f'{joint}_{self.p.spectrum_field}_amplitude',
                                         amplitude[:, k].tolist()), log_time=stamp)

    def _status_stamp(self, values: Mapping[str, str]) -> int:
        """Log time of a run-status message: its last step's stamp (0 before the first)."""
        try:
            return max(int(values.get('last_stamp_ns', 0)), 0)
        except ValueError:
            return 0

    def dropped(self) -> int:
        """Messages every stream lost (backlog full, never delivered) or could not decode."""
        return sum(s.dropped + s.rejected for s in list(self.streams.values()))

    def _send_status(self, wall: float) -> None:
        values = self.status.report(wall, self.dropped())
        stamp = max(self.status.newest, 0)
        if not self.channels[interface.LIVE_STATUS].has_sinks():
            return
        data = self.encoder.joint_state(stamp, '', list(STATUS_NAMES),
                                        {'position': np.asarray(values).tolist(),
                                         'velocity': [], 'effort': []})
        self.channels[interface.LIVE_STATUS].log(data, log_time=stamp)
