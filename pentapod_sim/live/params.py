"""Parameters of the live_view node (ROS-free; docs/live_view.md, docs/parameters.md)."""
from __future__ import annotations

from dataclasses import dataclass

from pentapod_sim.parameters import NodeParams, param

#: Address the WebSocket server binds to unless told otherwise: this machine only.
DEFAULT_HOST = '127.0.0.1'
DEFAULT_PORT = 8765


@dataclass(frozen=True)
class LiveViewParams(NodeParams):
    """
    Serves a run to Foxglove over its WebSocket protocol.

    The testbed topics (min/max envelopes at a display rate), a running TCP spectrum and the
    run status.
    """

    host: str = param(DEFAULT_HOST, 'address the Foxglove WebSocket server binds to; the default '
                      'serves this machine only, 0.0.0.0 every network interface (anyone who '
                      'reaches the port can read the run)')
    port: int = param(DEFAULT_PORT, 'TCP port of the WebSocket server; 0 = any free port '
                      '(logged)', bounds=(0, 65535))
    topics: tuple[str, ...] = param((), 'topics to serve; empty: every /pentapod/* topic of type '
                                    'sensor_msgs/JointState or geometry_msgs/WrenchStamped except '
                                    'the full-rate TCP topic (state and force topics come from '
                                    "the plant's display batches)")
    display_rate: float = param(100.0, 'envelope windows per simulated second; each window is '
                                'sent as two messages carrying its minimum and maximum', 'Hz',
                                bounds=(0.1, 1.0e6))
    spectrum_samples: int = param(4096, 'newest TCP samples per spectrum (resolution = sample '
                                  'rate / spectrum_samples)', bounds=(16, 2 ** 22))
    spectrum_field: str = param('position', 'TCP quantity of the spectrum: position '
                                '(displacement, m) or velocity (m/s)',
                                choices=('position', 'velocity'))
    spectrum_period: float = param(0.5, 'wall time between two spectra', 's',
                                   bounds=(0.01, 3600.0))
    status_period: float = param(0.5, 'wall time between two run status messages', 's',
                                 bounds=(0.01, 3600.0))
    tick_period: float = param(0.05, 'wall time between two passes of the worker thread '
                               '(decode, downsample, send)', 's', bounds=(0.001, 10.0))
    idle_flush: float = param(0.3, 'wall time without a new sample after which the open envelope '
                              'window of a topic is sent', 's', bounds=(0.01, 3600.0))
    queue_depth: int = param(2000, 'subscription history and worker backlog per topic '
                             '[messages]; more are dropped and counted in the run status',
                             bounds=(1, 10 ** 7))
    reliability: str = param('best_effort', 'subscription reliability: best_effort never makes '
                             'the plant hold, resend or wait for acknowledgements for the live '
                             'view', choices=('best_effort', 'reliable'))
    discovery_period: float = param(0.5, 'wall time between two looks for new topics', 's',
                                    bounds=(0.01, 3600.0))
    nice: int = param(10, 'niceness added to every thread of the live view process: on a busy '
                      'machine the scheduler gives the plant and its controllers the CPU first '
                      'and the view falls behind instead (its best-effort subscriptions drop '
                      'samples)', bounds=(0, 19))
