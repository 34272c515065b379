"""
The Foxglove layout of the testbed (config/foxglove/testbed_layout.json), built from code.

The layout plots message paths of the ROS topic names, which the live view serves with the
same names and types as the bags hold, so one layout works live and on a recorded bag: TCP
displacement and velocity, the forces of every source of the shipped scenarios (one tab per
source), the PMA stroke and force, the plant's run-status messages (/pentapod/run_status, text
keys), and from the live view only the TCP spectrum and the run figures. It is written in the
layout file format that Foxglove's and Lichtblick's "Import layout from file" read
(``configById`` + ``layout`` tree). Regenerate after a change with::

    python -m pentapod_sim.live.layout > config/foxglove/testbed_layout.json

test/test_live_view.py checks that the committed file equals :func:`layout_json`.
"""
from __future__ import annotations

import json
from typing import Any, Sequence

from pentapod_sim import interface
from pentapod_sim.live.status import status_index
from pentapod_sim.plant.ports import AXES, N_STRUTS, OUTPUT_NAMES
from pentapod_sim.scenario.files import read_scenario, scenario_names

#: Simulated seconds a live plot shows (Foxglove's "following" view width).
FOLLOW_S = 2.0
#: Effort series per force source: the TCP / PMA force ports (x, y, z) or, for a damper, up
#: to the strut ports (two bending axes and the axial direction of each strut).
EFFORTS = {'exciter': len(AXES), 'pma': len(AXES), 'damper_tcp': len(AXES)}
DAMPER_EFFORTS = 3 * N_STRUTS


#: A layout's configuration or panel tree: Foxglove's JSON
Json = dict[str, Any]
#: A split of the panel tree, or one panel id
Tree = Json | str


def _series(value: str, label: str, timestamp: str = 'headerStamp') -> Json:
    return {'value': value, 'enabled': True, 'timestampMethod': timestamp, 'label': label}


def _plot(title: str, series: list[Json], y_label: str = '', **extra: Any) -> Json:
    config = {'title': title, 'paths': series, 'showXAxisLabels': True,
              'showYAxisLabels': True, 'showLegend': True, 'legendDisplay': 'floating',
              'showPlotValuesInLegend': False, 'isSynced': True, 'xAxisVal': 'timestamp',
              'sidebarDimension': 240, 'followingViewWidth': FOLLOW_S}
    if y_label:
        config['yAxisLabel'] = y_label
    config.update(extra)
    return config


def _joints(topic: str) -> list[str]:
    """Joint order of a state topic for the full port list (the plant's order)."""
    for lay in interface.state_layouts(OUTPUT_NAMES):
        if lay.topic == topic:
            return lay.joints
    raise KeyError(topic)


def scenario_sources() -> list[str]:
    """Force source names of the shipped scenarios, in order of first use."""
    names: list[str] = []
    for scenario in scenario_names():
        parsed = read_scenario(scenario)
        plant = parsed.of_kind('plant')[0].name
        names += [s for s in parsed.sections[plant].get('sources') or [] if s not in names]
    return names


def _split(first: Tree, second: Tree, direction: str, percent: float = 50.0) -> Json:
    return {'first': first, 'second': second, 'direction': direction,
            'splitPercentage': percent}


def _row(ids: Sequence[Tree], direction: str = 'row') -> Tree:
    """Even split of panel ids (or subtrees)."""
    if len(ids) == 1:
        return ids[0]
    return _split(ids[0], _row(ids[1:], direction), direction, 100.0 / len(ids))


def build_layout() -> Json:
    """The layout as a dict (see the module docstring)."""
    tcp = _joints(interface.TCP_STATE)
    cfg: dict[str, Json] = {}
    cfg['Plot!tcp_displacement'] = _plot('TCP displacement [m]', [
        _series(f'{interface.TCP_STATE}.position[{i}]', j) for i, j in enumerate(tcp)], 'm')
    cfg['Plot!tcp_velocity'] = _plot('TCP velocity [m/s]', [
        _series(f'{interface.TCP_STATE}.velocity[{i}]', j) for i, j in enumerate(tcp)], 'm/s')
    freq = interface.tcp_spectrum_topic('frequency')
    cfg['Plot!tcp_spectrum'] = _plot(
        'TCP amplitude spectrum, live only [m over Hz]',
        [_series(f'{interface.tcp_spectrum_topic(j)}.data[:]', j, 'receiveTime') for j in tcp],
        'm', xAxisVal='currentCustom', xAxisPath={'value': f'{freq}.data[:]', 'enabled': True},
        xAxisLabel='Hz')
    tabs = [{'title': 'excitation', 'layout': 'Plot!force_excitation'}]
    cfg['Plot!force_excitation'] = _plot('Excitation force [N]', [
        _series(f'{interface.EXCITATION}.wrench.force.{a}', f'force {a}') for a in AXES], 'N')
    for source in scenario_sources():
        count = EFFORTS.get(source, DAMPER_EFFORTS if source.startswith('damper') else len(AXES))
        panel = f'Plot!force_{source}'
        cfg[panel] = _plot(f'Forces of source {source} [N or N m]', [
            _series(f'{interface.force_topic(source)}.effort[{i}]', f'effort[{i}]')
            for i in range(count)], 'N, N m')
        tabs.append({'title': source, 'layout': panel})
    cfg['Tab!forces'] = {'title': 'Forces per source', 'activeTabIdx': 0, 'tabs': tabs}
    cfg['Plot!pma_stroke'] = _plot('PMA stroke [m]', [
        _series(f'{interface.PMA_STATE}.position[{i}]', f'stroke[{i}]') for i in range(3)], 'm')
    cfg['Plot!pma_force'] = _plot('PMA force on the structure [N]', [
        _series(f'{interface.PMA_STATE}.effort[{i}]', f'force[{i}]') for i in range(3)], 'N')
    cfg['Plot!run_rate'] = _plot('Run status, live only', [
        _series(f'{interface.LIVE_STATUS}.position[{status_index(name)}]', name)
        for name in ('steps_per_second', 'real_time_factor')])
    cfg['Plot!run_counters'] = _plot('Run counters, live only', [
        _series(f'{interface.LIVE_STATUS}.position[{status_index(name)}]', name)
        for name in ('deadline_misses', 'rejected_messages', 'dropped_by_live_view')])
    cfg['RawMessages!run_status'] = {
        'topicPath': interface.RUN_STATUS, 'diffEnabled': False, 'diffMethod': 'custom',
        'diffTopicPath': '', 'showFullMessageForDiff': False}
    tree = _row([
        _row(['Plot!tcp_displacement', 'Plot!tcp_velocity', 'Plot!tcp_spectrum']),
        _row(['Tab!forces', 'Plot!pma_stroke', 'Plot!pma_force']),
        _row(['Plot!run_rate', 'Plot!run_counters', 'RawMessages!run_status']),
    ], 'column')
    return {'configById': cfg, 'globalVariables': {}, 'userNodes': {},
            'playbackConfig': {'speed': 1.0}, 'layout': tree}


def layout_json() -> str:
    """The committed file's text."""
    return json.dumps(build_layout(), indent=2) + '\n'


def message_paths(layout: Json) -> list[str]:
    """Every message path a layout plots or shows (series, x axes, raw message topics)."""
    found = []
    for config in layout['configById'].values():
        found += [p['value'] for p in config.get('paths', [])]
        if 'xAxisPath' in config:
            found.append(config['xAxisPath']['value'])
        if 'topicPath' in config:
            found.append(config['topicPath'])
    return found


def main() -> int:
    """Print the layout (``python -m pentapod_sim.live.layout > file``)."""
    print(layout_json(), end='')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
