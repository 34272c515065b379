"""
Scenario files of the tuned strut laws, written from the damper table's records.

One file per law a damper node runs (IFF, lag displacement on bending and chord ports,
band-pass velocity, PPF) with the gains tuned at one position (``python -m
pentapod_damper.design --scenarios config/scenarios``), so the shipped files cannot drift from
the table (test/test_damper_docs.py). The lag and PPF stiffnesses are written per port: the
tuned fraction times each strut's reference stiffness at that position. IFF inside the drives'
loops (HAC-LAC) and the drives alone run on the plant with the drives' rotors (plant parameter
``drives``), their cascade in the damper node (``drive_struts``).

Units: SI, as the damper node's parameters (docs/parameters.md).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from pentapod_damper.design.report import Record
from pentapod_sim.sim.law_families import StrutStiffness

#: Table row -> (scenario name, what it is).
SCENARIOS = {
    'IFF': ('iff_struts', 'integral force feedback from the load cells to force actuators at '
                          'the nuts'),
    'lag displacement, bending': ('lag_bending_struts', 'lag displacement feedback on the '
                                                        'strut bending ports'),
    'lag displacement, chord': ('lag_chord_struts', 'lag displacement feedback on the strut '
                                                    'chord ports'),
    'band-pass velocity, bending': ('bandpass_struts', 'velocity feedback through a band-pass '
                                                       'on the strut bending ports'),
    'PPF, bending': ('ppf_struts', 'positive position feedback on the strut bending ports'),
    'IFF + position loop (HAC-LAC)': ('hac_lac_struts', "integral force feedback inside the "
                                                        "feed drives' position loops (HAC-LAC)"),
    'feed drives alone (position loops)': ('drives_struts', "the feed drives' position loops "
                                                            'alone'),
}
#: The drives file of the scenarios with the drives (config/drives.yaml, as the table's).
DRIVES = 'drives.yaml'
#: The plant's divergence bound with the drives: their state holds the motors' forces [N]
#: (about 4 kN at P1 in HAC-LAC's periodic start under a 10 N multisine), above the default
#: bound of 1e3 meant for modal coordinates.
DRIVES_STATE_NORM = 1e6
STRUTS = [1, 2, 3, 4, 5]


def gains_of(record: Record) -> dict[str, float]:
    """The tuned values of a record's ``gains`` text."""
    if record['gains'] == '-':
        return {}
    return {k: float(v) for k, v in (item.split(' ') for item in record['gains'].split('; '))}


def _ports(stiff: StrutStiffness, kind: str) -> list[float]:
    table = stiff.bending if kind == 'bending' else stiff.chord
    return [float(table[i - 1, k]) for i in STRUTS for k in (0, 1)]


def node_params(record: Record, stiff: StrutStiffness) -> dict[str, Any]:
    """The damper node's parameters of a tuned record (see :data:`SCENARIOS`)."""
    g, law = gains_of(record), record['law']
    if law == 'IFF':
        return {'iff_struts': STRUTS, 'iff_gain': g['gain'],
                'iff_omega': g['omega_ratio'] * g['gain'], 'filter_order': 2,
                'bandwidth_hz': g['lowpass_hz']}
    if law.startswith('lag displacement'):
        kind = 'bending' if law.endswith('bending') else 'chord'
        return {'lag_struts': STRUTS, 'lag_port': kind,
                'lag_stiffness': [g['stiffness_ratio'] * k for k in _ports(stiff, kind)],
                'lag_corner_hz': g['corner_hz']}
    if law.startswith('band-pass'):
        return {'bandpass_struts': STRUTS, 'bandpass_port': 'bending', 'bandpass_gain': g['gain'],
                'bandpass_highpass_hz': g['highpass_hz'], 'bandpass_lowpass_hz': g['lowpass_hz']}
    if law.startswith('IFF + position loop'):
        return {'drive_struts': STRUTS, 'drive_file': DRIVES, 'drive_iff_gain': g['gain'],
                'drive_iff_omega': g['omega_ratio'] * g['gain'], 'filter_order': 2,
                'bandwidth_hz': g['lowpass_hz']}
    if law.startswith('feed drives alone'):
        return {'drive_struts': STRUTS, 'drive_file': DRIVES}
    if law.startswith('PPF'):
        sensors = [f'strut{i}_bending_{k}' for i in STRUTS for k in (2, 3)]
        return {'ppf_struts': STRUTS, 'ppf_port': 'bending',
                'ppf_stiffness': [g['gain_ratio'] / stiff.port_static[s] for s in sensors],
                'ppf_frequency_hz': g['frequency_ratio'] * float(record['baseline_peak_hz']),
                'ppf_damping': g['damping']}
    raise KeyError(law)


def _value(value: Any) -> str:
    if isinstance(value, list):
        return '[' + ', '.join(_value(v) for v in value) + ']'
    if isinstance(value, float):
        return repr(float(f'{value:.6g}'))
    return str(value)


def scenario_text(record: Record, params: Mapping[str, Any]) -> str:
    """The scenario file of one tuned record."""
    name, what = SCENARIOS[record['law']]
    rate = float(record['sample_rate_hz'])
    lines = [
        f'# Scenario {name}: {what}, tuned at {record["position"]}',
        '# Generated by `python -m pentapod_damper.design --scenarios config/scenarios` from the',
        '# damper table (docs/dampers.md, docs/results/dampers.csv): at '
        f'{record["position"]} TCP {record["direction"]}{record["direction"]} peak '
        f'{float(record["peak_reduction"]):.2f}x lower,',
        f'# static compliance x{float(record["static_ratio"]):.3f}, check-model margin '
        f'{float(record["check_margin"]):.1e} ({float(record["check_margin_extra_delay"]):.1e} '
        'with one more sample of delay).',
        '# ROS 2 parameter file (one section per node; `/**` applies to every node). Start it '
        'with',
        f'#   ros2 run pentapod_testbed scenario {name}        (or: python -m '
        f'pentapod_sim.scenario {name})',
        '/**:', '  ros__parameters:',
        f'    sample_rate: {_value(rate)}            # plant sample rate [Hz] (the tuned rate)',
        '', 'plant:', '  ros__parameters:',
        f'    position: {record["position"]}                   # the position the gains were '
        'tuned at', *([f"    drives: {DRIVES}            # the feed drives' rotors (config/"
                       'drives.yaml)',
                       f'    max_state_norm: {_value(DRIVES_STATE_NORM)}       # the state holds '
                       "the motors' forces [N] (kN in a 10 N multisine run)"]
                      if 'drive_struts' in params else []),
        '    timing: lockstep               # lockstep | realtime',
        '    duration: 4.0                  # simulated time [s]',
        '    sources: [exciter, damper_struts]',
        '    source_timeout: 5.0            # [s] wall time a source may stay silent',
        "    output_file: ''                # .npz trace of y_k, u_k (empty: none)",
        '    wait_for_subscribers: [recorder]   # step 0 waits until the recorder is matched',
        '', 'exciter:', '  ros__parameters:',
        '    kind: random                   # band-limited Gaussian force at the TCP',
        '    amplitude: 100.0               # RMS force [N]',
        '    direction: [1.0, 0.0, 0.0]     # along machine x',
        '    f_start: 2.0                   # band [Hz]', '    f_end: 400.0',
        '    duration: 4.0                  # [s]', '    seed: 1',
        '', 'damper_struts:', '  ros__parameters:']
    lines += [f'    {key}: {_value(value)}' for key, value in params.items()]
    lines += [f'    delay_steps: {record["delay_steps"]}                 # the tuned '
              'computational delay [samples]',
              '', 'recorder:                          # records the run (docs/recording.md)',
              '  ros__parameters:',
              '    output_dir: out/bags           # relative to the working folder',
              f'    bag_name: {name}-{{utc}}']
    return '\n'.join(lines) + '\n'


def shipped_records(records: list[Record], position: str) -> list[Record]:
    """
    The records the scenario files hold: ``position``, locked machine, the largest delay.

    With a sample of computational delay the laws are what a digital controller runs (and
    they were kept stable with one more); the table's delay-0 rows are the testbed's plain
    sampled feedback.
    """
    mine = [r for r in records if (r['position'], r['machine']) == (position, 'locked')
            and r['law'] in SCENARIOS]
    delay = max((int(r['delay_steps']) for r in mine), default=0)
    return [r for r in mine if int(r['delay_steps']) == delay]


def write_scenarios(records: list[Record], stiff: StrutStiffness, position: str,
                    folder: str | Path) -> list[Path]:
    """Write the scenario files of :func:`shipped_records`."""
    folder = Path(folder)
    out = []
    for record in shipped_records(records, position):
        if record['law'] in SCENARIOS:
            path = folder / f'{SCENARIOS[record["law"]][0]}.yaml'
            path.write_text(scenario_text(record, node_params(record, stiff)))
            out.append(path)
    return out
