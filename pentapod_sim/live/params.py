"""Parameter table of the live_view node (ROS-free; docs/live_view.md, docs/parameters.md)."""
from __future__ import annotations

from pentapod_sim.parameters import Param, ParameterTable

#: Address the WebSocket server binds to unless told otherwise: this machine only.
DEFAULT_HOST = '127.0.0.1'
DEFAULT_PORT = 8765

LIVE_VIEW = ParameterTable('live_view', [
    Param('host', 'str', DEFAULT_HOST, 'address the Foxglove WebSocket server binds to; the '
          'default serves this machine only, 0.0.0.0 every network interface (anyone who '
          'reaches the port can read the run)'),
    Param('port', 'int', DEFAULT_PORT, 'TCP port of the WebSocket server; 0 = any free port '
          '(logged)', '', 0, 65535),
    Param('topics', 'string[]', [], 'topics to serve; empty: every /pentapod/* topic of type '
          'sensor_msgs/JointState or geometry_msgs/WrenchStamped except the full-rate TCP '
          "topic (state and force topics come from the plant's display batches)"),
    Param('display_rate', 'float', 100.0, 'envelope windows per simulated second; each window '
          'is sent as two messages carrying its minimum and maximum', 'Hz', 0.1, 1.0e6),
    Param('spectrum_samples', 'int', 4096, 'newest TCP samples per spectrum (resolution = '
          'sample rate / spectrum_samples)', '', 16, 2 ** 22),
    Param('spectrum_field', 'str', 'position', 'TCP quantity of the spectrum: position '
          '(displacement, m) or velocity (m/s)', choices=('position', 'velocity')),
    Param('spectrum_period', 'float', 0.5, 'wall time between two spectra', 's', 0.01, 3600.0),
    Param('status_period', 'float', 0.5, 'wall time between two run status messages', 's',
          0.01, 3600.0),
    Param('tick_period', 'float', 0.05, 'wall time between two passes of the worker thread '
          '(decode, downsample, send)', 's', 0.001, 10.0),
    Param('idle_flush', 'float', 0.3, 'wall time without a new sample after which the open '
          'envelope window of a topic is sent', 's', 0.01, 3600.0),
    Param('queue_depth', 'int', 2000, 'subscription history and worker backlog per topic '
          '[messages]; more are dropped and counted in the run status', '', 1, 10 ** 7),
    Param('reliability', 'str', 'best_effort', 'subscription reliability: best_effort never '
          'makes the plant hold, resend or wait for acknowledgements for the live view',
          choices=('best_effort', 'reliable')),
    Param('discovery_period', 'float', 0.5, 'wall time between two looks for new topics', 's',
          0.01, 3600.0),
    Param('nice', 'int', 10, 'niceness added to every thread of the live view process: on a '
          'busy machine the scheduler gives the plant and its controllers the CPU first and '
          'the view falls behind instead (its best-effort subscriptions drop samples)', '',
          0, 19),
], summary='serves the testbed topics (min/max envelopes at a display rate), a running TCP '
           'spectrum and the run status to Foxglove over its WebSocket protocol.')
