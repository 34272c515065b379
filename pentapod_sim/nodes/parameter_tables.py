"""
Parameter tables of the plant, exciter and recorder nodes (ROS-free; docs/parameters.md).

Also the parameters every lockstep force source shares (:data:`SOURCE_PARAMS`) and the one
``sample_rate`` of plant, exciter and PMA (:data:`SAMPLE_RATE`). The exciter's signal defaults
are those of :class:`pentapod_sim.sim.excitation.ExcitationSpec`; :func:`excitation_spec`
turns the exciter's values into that spec.
"""
from __future__ import annotations

import math

from pentapod_sim.parameters import Param, ParameterTable, Values
from pentapod_sim.plant.check_band import DEFAULT_CHECK_F_MIN
from pentapod_sim.sim.excitation import ExcitationSpec, KINDS, PHASES, PULSE_SHAPES
from pentapod_sim.sim.multirate import MAX_SUBSTEPS
from pentapod_sim.sim.stepping import DEFAULT_MAX_STATE_NORM

#: The plant's sample rate; the exciter and the PMA must be given the same.
SAMPLE_RATE = Param('sample_rate', 'float', 5000.0, 'plant sample rate (exciter and PMA: '
                    "the same as the plant's)", 'Hz', 1.0, 1.0e6)

#: Parameters of every lockstep force source (:class:`..lockstep_source.LockstepSource`).
SOURCE_PARAMS = (
    Param('source_name', 'str', '', 'publishes forces on /pentapod/forces/<source_name>; '
          "empty: the node's name (the declared default)"),
    Param('wait_for_subscribers', 'string[]', [], 'node names (e.g. a recorder) that must be '
          "subscribed and matched to this node's information topics before it answers step 0 "
          '(the plant re-sends step 0 meanwhile)'),
)

PLANT = ParameterTable('plant', [
    Param('model_file', 'str', '', 'saved PlantModel .npz; wins over position'),
    Param('position', 'str', 'P1', 'position name of config/positions.yaml to build the model '
          'for (cached)'),
    Param('model_cache_dir', 'str', 'out/models', 'folder of cached built models'),
    SAMPLE_RATE,
    Param('substeps', 'int', 1, 'plant steps per exchange: the plant integrates at '
          'sample_rate * substeps (exact zero-order hold, forces held over the substeps) and '
          'exchanges /clock, states and forces at sample_rate; the full-rate outputs go to '
          '/pentapod/tcp_state_fullrate and output_file', '', 1, MAX_SUBSTEPS),
    Param('timing', 'str', 'lockstep', 'lockstep: wait for every source each step; realtime: '
          'y_k published at the start of period k, u_k applied if it arrives before the end '
          'of the period, else the last force held and the miss counted',
          choices=('lockstep', 'realtime')),
    Param('duration', 'float', 1.0, 'simulated time (if steps is 0)', 's', 0.0, 1.0e7),
    Param('steps', 'int', 0, 'number of steps; 0 = use duration', '', 0, 10 ** 12),
    Param('sources', 'string[]', [], 'force source names; each publishes on '
          '/pentapod/forces/<name>'),
    Param('source_ports.<source>', 'string[]', [], 'input ports this source may drive '
          '(empty: all)'),
    Param('source_timeout', 'float', 5.0, 'lockstep: max wall time a source may stay silent',
          's', 1e-3, 3600.0),
    Param('startup_timeout', 'float', 30.0, 'max wall time to wait for the sources at step 0 '
          '(and for wait_for_subscribers)', 's', 0.0, 3600.0),
    Param('resend_period', 'float', 0.2, 'lockstep: re-publish y_k after this wall time '
          'without all answers', 's', 1e-3, 60.0),
    Param('answer_poll_time', 'float', 1e-3, 'lockstep: poll for the answers this long after '
          'publishing y_k before blocking in the executor, while the plant and every other '
          'process that works each step have a CPU each (0: never poll)', 's', 0.0, 1.0),
    Param('max_state_norm', 'float', DEFAULT_MAX_STATE_NORM, 'instability bound on the norm '
          'of the modal state ||x||; larger or NaN stops the run', '', 1e-12, 1e150),
    Param('report_period', 'float', 2.0, 'realtime: log timing every this wall time', 's',
          0.1, 3600.0),
    Param('output_file', 'str', '', 'write y_k, u_k of every step to this .npz at the end '
          '(empty: no file)'),
    Param('wait_for_subscribers', 'string[]', [], 'node names (e.g. a recorder) that must '
          'subscribe to an output topic before step 0'),
    Param('subscriber_settle', 'float', 0.5, 'wall time spun after the wait_for_subscribers '
          'nodes appeared', 's', 0.0, 60.0),
    Param('ack_timeout', 'float', 60.0, 'max wall time to wait at the end until subscribers '
          'acknowledged every message (a recorder repairing a stall needs a while)', 's', 0.0,
          3600.0),
    Param('max_effort', 'float', 1.0e6, 'largest accepted |effort| per input port; larger '
          'efforts are rejected and counted like NaN', 'N or N m', 0.0, 1e300),
    Param('shared_source_topics', 'bool', False, 'accept a force topic with more than one '
          'publisher (default: refused, naming the publishers)'),
    Param('lost_source_policy', 'str', 'zero', 'realtime: force of a source whose publisher '
          'left the graph (zero, or hold its last force); lockstep stops the run',
          choices=('zero', 'hold')),
    Param('loop_check', 'str', 'warn', 'truncation check before step 0 with the linear models '
          'the sources publish: refuse = end with an error, warn = log a loud warning, when '
          'the sampled loop is unstable on the plant or stable only thanks to truncation (the '
          "check model of the model's position: FE modes below max(loop_check_f_min, 2 x "
          'sample_rate)); off = no check', choices=('refuse', 'warn', 'off')),
    Param('loop_check_f_min', 'float', DEFAULT_CHECK_F_MIN, 'lowest cut-off of the check '
          "model's modes (cached in model_cache_dir)", 'Hz', 1.0, 1.0e7),
    Param('status_period', 'float', 0.5, 'wall time between run-status messages during a run '
          '(/pentapod/run_status: steps, step_rate, deadline_misses, rejected_messages)', 's',
          0.01, 3600.0),
    Param('display_batch_period', 'float', 0.01, 'simulated time per message of the display '
          'batches (/pentapod/live/batch/*, published only while subscribed, e.g. by the '
          'live view): one sensor_msgs/JointState per state topic and per force source carries '
          'the values of round(display_batch_period / dt) steps (at least 1)', 's', 0.0, 10.0),
], summary='integrates the modal plant; publishes /clock and the state topics, applies the '
           'forces of its sources.')

_SPEC = ExcitationSpec()

EXCITER = ParameterTable('exciter', [
    SAMPLE_RATE,
    Param('kind', 'str', _SPEC.kind, 'signal (docs/nodes.md, "Excitation signals")',
          choices=KINDS),
    Param('amplitude', 'float', _SPEC.amplitude, 'peak force (RMS for random)', 'N', -1e9, 1e9),
    Param('direction', 'double[]', [float(v) for v in _SPEC.direction], 'force direction x, y, '
          'z in the machine frame (normalised)'),
    Param('frequency', 'float', _SPEC.frequency, 'sine frequency', 'Hz', 0.0, 1e6),
    Param('f_start', 'float', _SPEC.f_start, 'band low edge: chirp start, random, multisine, '
          'periodic chirp, stepped-sine lines', 'Hz', 0.0, 1e6),
    Param('f_end', 'float', _SPEC.f_end, 'band high edge (chirp end)', 'Hz', 0.0, 1e6),
    Param('duration', 'float', 0.0, 'signal length; 0 = endless (impulse, step, sine, '
          'multisine, periodic chirp, stepped sine)', 's', 0.0, 1e7),
    Param('start_delay', 'float', _SPEC.start_delay, 'time of the first sample of the signal',
          's', 0.0, 1e7),
    Param('pulse_width', 'float', _SPEC.pulse_width, 'impulse length; 0 = one sample', 's',
          0.0, 1e3),
    Param('pulse_shape', 'str', _SPEC.pulse_shape, 'impulse shape', choices=PULSE_SHAPES),
    Param('seed', 'int', _SPEC.seed, 'random seed (random signal, random multisine phases)',
          '', 0, 2 ** 31),
    Param('period', 'float', _SPEC.period, 'period of multisine and periodic chirp (a whole '
          'number of samples); multisine lines are its multiples', 's', 0.0, 1e6),
    Param('phases', 'str', _SPEC.phases, 'multisine phases (schroeder: low crest factor)',
          choices=PHASES),
    Param('frequencies', 'double[]', [], 'multisine lines (multiples of 1/period) or '
          'stepped-sine frequencies; empty: from f_start to f_end', 'Hz'),
    Param('line_spacing', 'float', _SPEC.line_spacing, 'stepped sine: spacing of the lines '
          'from f_start to f_end', 'Hz', 0.0, 1e6),
    Param('settle_time', 'float', _SPEC.settle_time, 'stepped sine: time at each line before '
          'its measurement window', 's', 0.0, 1e6),
    Param('periods_per_line', 'int', _SPEC.periods_per_line, 'stepped sine: whole periods in '
          'each measurement window', '', 1, 10 ** 6),
    Param('settle_periods', 'int', _SPEC.settle_periods, 'multisine, periodic chirp: leading '
          'periods the analysis discards', '', 0, 10 ** 6),
    *SOURCE_PARAMS,
], summary='a force at the TCP (impulse, step, sine, chirp, band-limited random, multisine, '
           'periodic chirp, stepped sine), answering every /clock tick.')

RECORDER = ParameterTable('recorder', [
    Param('topics', 'string[]', [], 'topics to record; empty: every /pentapod/* topic and '
          '/clock'),
    Param('output_dir', 'str', 'out/bags', 'folder of bags'),
    Param('bag_name', 'str', '', 'bag folder name, {utc} replaced by the UTC time '
          '(20260101T120000Z); empty: run-{utc}'),
    Param('run_info', 'str', '', "YAML mapping stored in the bag's custom_data (model hash, "
          'pose, scenario)'),
    Param('queue_depth', 'int', 100000, 'subscription depth (messages held while the writer '
          'catches up)', '', 1, 2 ** 31 - 1),
    Param('discovery_period', 'float', 0.2, 'wall time between looks for new topics', 's',
          1e-3, 3600.0),
    Param('flush_period', 'float', 0.5, 'wall time between flushes of the bag to disk', 's',
          1e-3, 3600.0),
    Param('stop_at_run_end', 'bool', True, 'close the bag and exit once the plant announced '
          'the end of the run and every per-step topic holds its last step (false: run until '
          'SIGINT/SIGTERM)'),
    Param('drain_timeout', 'float', 30.0, 'wall time after the end announcement after which '
          'the bag is closed even if steps are missing (they are reported)', 's', 0.0, 1e6),
], summary='writes chosen topics to a rosbag2-compatible MCAP bag.')


def excitation_spec(values: Values) -> ExcitationSpec:
    """The exciter's signal from its parameter values (duration 0 = endless)."""
    return ExcitationSpec(
        kind=values.kind, amplitude=values.amplitude, direction=values.direction,
        frequency=values.frequency, f_start=values.f_start, f_end=values.f_end,
        duration=values.duration or math.inf, start_delay=values.start_delay,
        pulse_width=values.pulse_width, seed=values.seed, period=values.period,
        phases=values.phases, frequencies=list(values.frequencies),
        line_spacing=values.line_spacing, settle_time=values.settle_time,
        periods_per_line=values.periods_per_line, settle_periods=values.settle_periods,
        pulse_shape=values.pulse_shape)
