"""
Parameters of the plant, exciter, cutting and recorder nodes (ROS-free; docs/parameters.md).

Each is a :class:`pentapod_sim.parameters.NodeParams` dataclass: the nodes declare them and
read their typed values, scenario files are checked against them. The exciter's signal
defaults are those of :class:`pentapod_sim.sim.excitation.ExcitationSpec`;
:meth:`ExciterParams.spec` turns its values into that spec; :meth:`CuttingParams.spec` turns
the cutting node's into its operation (config/machining.yaml and the overrides).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_process import CuttingConditions
from pentapod_sim.machining.cutting_spec import CuttingSpec
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.milling_cut import MILLING_MODES, MillingCut
from pentapod_sim.parameters import NodeParams, param, Sampled, SourceParams
from pentapod_sim.plant.check_band import DEFAULT_CHECK_F_MIN
from pentapod_sim.sim.excitation import ExcitationSpec, KINDS, PHASES, PULSE_SHAPES
from pentapod_sim.sim.multirate import MAX_SUBSTEPS
from pentapod_sim.sim.stepping import DEFAULT_MAX_STATE_NORM


@dataclass(frozen=True)
class PlantParams(Sampled):
    """
    Integrates the modal plant.

    Publishes /clock and the state topics, applies the forces of its sources.
    """

    model_file: str = param('', 'saved PlantModel .npz; wins over position')
    position: str = param('P1', 'position name of config/positions.yaml to build the model for '
                          '(cached)')
    model_cache_dir: str = param('out/models', 'folder of cached built models')
    initial_state_file: str = param('', 'start from this plant state instead of rest: a .npz '
                                    'with x (the plant state at step 0, as the plant steps it) '
                                    'and optionally u_previous (the input of step -1), e.g. the '
                                    'periodic steady state of a multisine (pentapod_sim.sim.'
                                    'periodic_state); empty: from rest. The run status and the '
                                    "bag's metadata name it")
    drives: str = param('', "feed drives file (e.g. drives.yaml: a bare name is looked up in "
                        "the package's config folder): the plant steps the modal plant with "
                        "the drives' rotors of drive_struts, discretised exactly at its step, "
                        'with the ports strut<i>_motor_force [N] in and strut<i>_motor_position '
                        "[m], strut<i>_motor_velocity [m/s] out (docs/dampers.md); the rotors "
                        "need their servo loops (a damper node's drive_struts). Empty: no "
                        'drives, the links locked as in the FE model')
    drive_struts: tuple[int, ...] = param((1, 2, 3, 4, 5), 'struts (1..5) whose feed drives '
                                          'the plant steps when drives is set')
    substeps: int = param(1, 'plant steps per exchange: the plant integrates at sample_rate * '
                          'substeps (exact zero-order hold, forces held over the substeps) and '
                          'exchanges /clock, states and forces at sample_rate; the full-rate '
                          'outputs go to /pentapod/tcp_state_fullrate and output_file',
                          bounds=(1, MAX_SUBSTEPS))
    timing: str = param('lockstep', 'lockstep: wait for every source each step; realtime: y_k '
                        'published at the start of period k, u_k applied if it arrives before '
                        'the end of the period, else the last force held and the miss counted',
                        choices=('lockstep', 'realtime'))
    duration: float = param(1.0, 'simulated time (if steps is 0)', 's', bounds=(0.0, 1.0e7))
    steps: int = param(0, 'number of steps; 0 = use duration', bounds=(0, 10 ** 12))
    sources: tuple[str, ...] = param((), 'force source names; each publishes on '
                                     '/pentapod/forces/<name>')
    source_ports: dict[str, tuple[str, ...]] = param(
        {}, 'input ports this source may drive (empty: all)', keys='sources')
    source_timeout: float = param(5.0, 'lockstep: max wall time a source may stay silent', 's',
                                  bounds=(1e-3, 3600.0))
    startup_timeout: float = param(30.0, 'max wall time to wait for the sources at step 0 (and '
                                   'for wait_for_subscribers)', 's', bounds=(0.0, 3600.0))
    resend_period: float = param(0.2, 'lockstep: re-publish y_k after this wall time without '
                                 'all answers', 's', bounds=(1e-3, 60.0))
    answer_poll_time: float = param(1e-3, 'lockstep: poll for the answers this long after '
                                    'publishing y_k before blocking in the executor, while the '
                                    'plant and every other process that works each step have a '
                                    'CPU each (0: never poll)', 's', bounds=(0.0, 1.0))
    max_state_norm: float = param(DEFAULT_MAX_STATE_NORM, 'instability bound on the norm of the '
                                  'state ||x|| in mass-normalised coordinates (the modal '
                                  'coordinates [sqrt(kg) m, sqrt(kg) m/s]; with drives the '
                                  "rotors' position and velocity times sqrt(m_r) and their "
                                  'motor force times sqrt(m_r) / k_a, so the same bound holds '
                                  'them as tightly); larger or NaN stops the run',
                                  bounds=(1e-12, 1e150))
    report_period: float = param(2.0, 'realtime: log timing every this wall time', 's',
                                 bounds=(0.1, 3600.0))
    output_file: str = param('', 'write y_k, u_k of every step to this .npz at the end (empty: '
                             'no file)')
    wait_for_subscribers: tuple[str, ...] = param((), 'node names (e.g. a recorder) that must '
                                                  'subscribe to an output topic before step 0')
    subscriber_settle: float = param(0.5, 'wall time spun after the wait_for_subscribers nodes '
                                     'appeared', 's', bounds=(0.0, 60.0))
    ack_timeout: float = param(60.0, 'max wall time to wait at the end until subscribers '
                               'acknowledged every message (a recorder repairing a stall needs '
                               'a while)', 's', bounds=(0.0, 3600.0))
    max_effort: float = param(1.0e6, 'largest accepted |effort| per input port; larger efforts '
                              'are rejected and counted like NaN', 'N or N m', bounds=(0.0, 1e300))
    shared_source_topics: bool = param(False, 'accept a force topic with more than one publisher '
                                       '(default: refused, naming the publishers)')
    lost_source_policy: str = param('zero', 'realtime: force of a source whose publisher left '
                                    'the graph (zero, or hold its last force); lockstep stops '
                                    'the run', choices=('zero', 'hold'))
    loop_check: str = param('warn', 'truncation check before step 0 with the linear models the '
                            'sources publish: refuse = end with an error, warn = log a loud '
                            'warning, when the sampled loop is unstable on the plant or stable '
                            "only thanks to truncation (the check model of the model's position: "
                            'FE modes below max(loop_check_f_min, 2 x sample_rate)); off = no '
                            'check', choices=('refuse', 'warn', 'off'))
    loop_check_f_min: float = param(DEFAULT_CHECK_F_MIN, "lowest cut-off of the check model's "
                                    'modes (cached in model_cache_dir)', 'Hz',
                                    bounds=(1.0, 1.0e7))
    status_period: float = param(0.5, 'wall time between run-status messages during a run '
                                 '(/pentapod/run_status: steps, step_rate, deadline_misses, '
                                 'rejected_messages)', 's', bounds=(0.01, 3600.0))
    display_batch_period: float = param(
        0.01, 'simulated time per message of the display batches (/pentapod/live/batch/*, '
        'published only while subscribed, e.g. by the live view): one sensor_msgs/JointState '
        'per state topic and per force source carries the values of round(display_batch_period '
        '/ dt) steps (at least 1)', 's', bounds=(0.0, 10.0))


_SPEC = ExcitationSpec()


@dataclass(frozen=True)
class ExciterParams(Sampled, SourceParams):
    """
    A force at the TCP, answering every /clock tick.

    Impulse, step, sine, chirp, band-limited random, multisine, periodic chirp, stepped sine.
    """

    kind: str = param(_SPEC.kind, 'signal (docs/nodes.md, "Excitation signals")', choices=KINDS)
    amplitude: float = param(_SPEC.amplitude, 'peak force (RMS for random)', 'N',
                             bounds=(-1e9, 1e9))
    direction: tuple[float, ...] = param(tuple(float(v) for v in _SPEC.direction),
                                         'force direction x, y, z in the machine frame '
                                         '(normalised)')
    frequency: float = param(_SPEC.frequency, 'sine frequency', 'Hz', bounds=(0.0, 1e6))
    f_start: float = param(_SPEC.f_start, 'band low edge: chirp start, random, multisine, '
                           'periodic chirp, stepped-sine lines', 'Hz', bounds=(0.0, 1e6))
    f_end: float = param(_SPEC.f_end, 'band high edge (chirp end)', 'Hz', bounds=(0.0, 1e6))
    duration: float = param(0.0, 'signal length; 0 = endless (impulse, step, sine, multisine, '
                            'periodic chirp, stepped sine)', 's', bounds=(0.0, 1e7))
    start_delay: float = param(_SPEC.start_delay, 'time of the first sample of the signal', 's',
                               bounds=(0.0, 1e7))
    pulse_width: float = param(_SPEC.pulse_width, 'impulse length; 0 = one sample', 's',
                               bounds=(0.0, 1e3))
    pulse_shape: str = param(_SPEC.pulse_shape, 'impulse shape', choices=PULSE_SHAPES)
    seed: int = param(_SPEC.seed, 'random seed (random signal, random multisine phases)',
                      bounds=(0, 2 ** 31))
    period: float = param(_SPEC.period, 'period of multisine and periodic chirp (a whole number '
                          'of samples); multisine lines are its multiples', 's',
                          bounds=(0.0, 1e6))
    phases: str = param(_SPEC.phases, 'multisine phases (schroeder: low crest factor)',
                        choices=PHASES)
    frequencies: tuple[float, ...] = param((), 'multisine lines (multiples of 1/period) or '
                                           'stepped-sine frequencies; empty: from f_start to '
                                           'f_end', 'Hz')
    line_spacing: float = param(_SPEC.line_spacing, 'stepped sine: spacing of the lines from '
                                'f_start to f_end', 'Hz', bounds=(0.0, 1e6))
    settle_time: float = param(_SPEC.settle_time, 'stepped sine: time at each line before its '
                               'measurement window', 's', bounds=(0.0, 1e6))
    periods_per_line: int = param(_SPEC.periods_per_line, 'stepped sine: whole periods in each '
                                  'measurement window', bounds=(1, 10 ** 6))
    settle_periods: int = param(_SPEC.settle_periods, 'multisine, periodic chirp: leading '
                                'periods the analysis discards', bounds=(0, 10 ** 6))

    def spec(self) -> ExcitationSpec:
        """The exciter's signal (duration 0 = endless)."""
        return ExcitationSpec(
            kind=self.kind, amplitude=self.amplitude, direction=list(self.direction),
            frequency=self.frequency, f_start=self.f_start, f_end=self.f_end,
            duration=self.duration or math.inf, start_delay=self.start_delay,
            pulse_width=self.pulse_width, seed=self.seed, period=self.period,
            phases=self.phases, frequencies=list(self.frequencies),
            line_spacing=self.line_spacing, settle_time=self.settle_time,
            periods_per_line=self.periods_per_line, settle_periods=self.settle_periods,
            pulse_shape=self.pulse_shape)


    def loop_laws(self, dt: float | None = None) -> list:
        """No law: the exciter reads no plant output, it closes no loop."""
        return []


#: Value of a cutting override that means "from the operation" (``milling``).
FROM_OPERATION = 'operation'


@dataclass(frozen=True)
class CuttingParams(Sampled, SourceParams):
    """
    Regenerative milling at the TCP, answering every plant step with the cutting force.

    An operation of the machining table (config/machining.yaml: material, end mill, radial
    immersion, up or down milling, feed) at a spindle speed and axial depth; any of its values
    may be overridden. The helix is ignored: every tooth engages the whole axial depth at one
    angle (pentapod_sim.machining.cutting_process).
    """

    operation: str = param('aluminium_half_down', 'operation of the machining table (material, '
                           'end mill, immersion, up/down milling, feed per tooth and direction)')
    machining_file: str = param('', 'machining table; empty: config/machining.yaml')
    spindle_speed: float = param(1500.0, 'spindle speed n', 'rpm', bounds=(1.0, 1.0e6))
    axial_depth: float = param(2.0e-4, 'axial depth of cut a', 'm', bounds=(1.0e-9, 1.0))
    teeth: int = param(0, "number of teeth N; 0: the operation's end mill", bounds=(0, 1000))
    feed_per_tooth: float = param(0.0, "feed per tooth f_t; 0: the operation's", 'm',
                                  bounds=(0.0, 0.1))
    radial_immersion: float = param(0.0, "radial depth over diameter a_e / D; 0: the "
                                    "operation's", bounds=(0.0, 1.0))
    milling: str = param(FROM_OPERATION, "up or down milling; operation: the operation's",
                         choices=(FROM_OPERATION, *MILLING_MODES))
    tangential_coefficient: float = param(0.0, "cutting coefficient K_tc; 0: the material's",
                                          'N/m^2', bounds=(0.0, 1.0e12))
    radial_ratio: float = param(-1.0, "K_rc / K_tc; negative: the material's",
                                bounds=(-1.0, 100.0))
    edge_tangential: float = param(-1.0, "edge coefficient K_te; negative: the material's",
                                   'N/m', bounds=(-1.0, 1.0e9))
    edge_radial: float = param(-1.0, "edge coefficient K_re; negative: the material's", 'N/m',
                               bounds=(-1.0, 1.0e9))

    def spec(self, source: str = '') -> CuttingSpec:
        """
        The operation as run: the table's operation with the overrides (ConfigError).

        ``source`` is the node's ``source_name`` recorded with it.
        """
        table = load_machining(self.machining_file or None)
        op = table.operation(self.operation)
        tool = table.tools[op.tool]
        k_tc, k_rc, k_te, k_re = table.materials[op.material].coefficients()
        tangential = self.tangential_coefficient or k_tc
        try:
            cut = MillingCut.from_immersion(
                self.teeth or tool.teeth, tangential,
                self.radial_ratio if self.radial_ratio >= 0 else k_rc / k_tc,
                self.radial_immersion or op.radial_immersion,
                op.milling if self.milling == FROM_OPERATION else self.milling, op.feed_angle)
            conditions = CuttingConditions(
                cut, self.spindle_speed, self.axial_depth, self.feed_per_tooth or
                op.feed_per_tooth, self.edge_tangential if self.edge_tangential >= 0 else k_te,
                self.edge_radial if self.edge_radial >= 0 else k_re)
        except ConfigError as err:
            raise ConfigError(f'cutting operation {self.operation!r}: {err}') from None
        return CuttingSpec(conditions, self.sample_rate, self.operation, source)

    def loop_laws(self, dt: float | None = None) -> list:
        """
        No law: the cut is the process whose stability the lobes judge, not a control law.

        Its linear model for the plant's truncation check is
        :func:`pentapod_sim.machining.cutting_model.regenerative_controller`.
        """
        return []


@dataclass(frozen=True)
class DisturbanceParams(Sampled, SourceParams):
    """
    Seeded white noise on chosen input ports, answering every /clock tick.

    Independent on each port: the excitation that identifies a controller in the loop (judge).
    """

    ports: tuple[str, ...] = param((), 'plant input ports, each driven by its own noise '
                                   '(e.g. the ports a controller answers)')
    amplitude: float = param(10.0, 'RMS of the noise on each port', 'N or N m',
                             bounds=(0.0, 1e9))
    seed: int = param(0, 'random seed', bounds=(0, 2 ** 31))

    def loop_laws(self, dt: float | None = None) -> list:
        """No law: the noise reads no plant output, it closes no loop."""
        return []


@dataclass(frozen=True)
class RecorderParams(NodeParams):
    """Writes chosen topics to a rosbag2-compatible MCAP bag."""

    topics: tuple[str, ...] = param((), 'topics to record; empty: every /pentapod/* topic and '
                                    '/clock')
    output_dir: str = param('out/bags', 'folder of bags')
    bag_name: str = param('', 'bag folder name, {utc} replaced by the UTC time '
                          '(20260101T120000Z); empty: run-{utc}')
    run_info: str = param('', "YAML mapping stored in the bag's custom_data (model hash, pose, "
                          'scenario)')
    fresh_topics: tuple[str, ...] = param((), 'topics recorded only from what their writers '
                                          'publish after the recorder matched them, none of '
                                          'their history (the answers of a source that outlives '
                                          "runs hold its earlier runs' steps)")
    queue_depth: int = param(100000, 'subscription depth (messages held while the writer catches '
                             'up)', bounds=(1, 2 ** 31 - 1))
    discovery_period: float = param(0.2, 'wall time between looks for new topics', 's',
                                    bounds=(1e-3, 3600.0))
    flush_period: float = param(0.5, 'wall time between flushes of the bag to disk', 's',
                                bounds=(1e-3, 3600.0))
    stop_at_run_end: bool = param(True, 'close the bag and exit once the plant announced the end '
                                  'of the run and every per-step topic holds its last step '
                                  '(false: run until SIGINT/SIGTERM)')
    drain_timeout: float = param(30.0, 'wall time after the end announcement without a new step '
                                 'message after which the bag is closed even if steps are '
                                 'missing (they are reported)', 's',
                                 bounds=(0.0, 1e6))
