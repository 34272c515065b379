"""
Draw the README's data-flow figure, docs/figures/dataflow.png: ``python docs/dataflow.py``.

The figure is drawn from :func:`spec`, which takes the topic names from
:mod:`pentapod_sim.interface` and names the folders and executables of each box; the spec is
stored in the PNG (text chunk ``pentapod_dataflow``), and test/test_docs.py checks that the
committed figure holds the spec the current code makes and that every topic, folder and
executable it names exists. Drawn with matplotlib rather than a diagram tool (graphviz and
friends are not dependencies of the package, and the figure is small).
"""
from __future__ import annotations

import json
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))                                # run from a checkout
from pentapod_sim import interface  # noqa: E402

FIGURE = ROOT / 'docs' / 'figures' / 'dataflow.png'
#: PNG text chunk that holds the spec the figure was drawn from
CHUNK = 'pentapod_dataflow'
LANES = (('model', 'Model (ROS-free)', '#dbe9f6'),
         ('run', 'Run (ROS 2 nodes)', '#fde8d0'),
         ('analysis', 'Analysis (ROS-free)', '#dcefdc'))


def spec() -> dict:
    """
    What the figure shows: boxes (lane, title, detail, folder or executable) and arrows.

    ``where`` of a box is a path in the repository (ends with ``/`` for a folder) or
    ``run:<executable>``; ``topics`` of an arrow are ROS topic names of the interface.
    """
    states = [interface.CLOCK, *interface.STATE_TOPICS]
    boxes = [
        ('config', 'model', 'machine data', 'struts, joints, frame,\npositions P1, P2',
         'config/'),
        ('fe', 'model', 'FE model', 'Timoshenko beams, cardan\njoints, one per position',
         'pentapod_sim/fe/'),
        ('modes', 'model', 'modes and causes', 'eigen solver,\nmodal strain energy',
         'pentapod_sim/modes/'),
        ('plant_model', 'model', 'reduced plant', 'dc-gain mode reduction,\n'
         'modal state space, ZOH', 'pentapod_sim/plant/'),
        ('plant', 'run', 'plant node', '$x_{k+1} = A_d x_k + B_d u_k$\n'
         '$y_k = C x_k + D u_{k-1}$', 'run:plant'),
        ('exciter', 'run', 'exciter', 'TCP force: random,\nmultisine, stepped sine',
         'run:exciter'),
        ('damper', 'run', 'damper', 'strut bending, axial,\nTCP to ground', 'run:damper'),
        ('pma', 'run', 'proof-mass actuator', 'proof mass at the TCP,\nhigh-pass, stroke limit',
         'run:pma'),
        ('controller', 'run', 'your controller', 'from the example node,\nin your package',
         'run:example_controller'),
        ('recorder', 'run', 'recorder', 'MCAP, no losses', 'run:recorder'),
        ('live_view', 'run', 'live view', 'Foxglove WebSocket', 'run:live_view'),
        ('bag', 'analysis', 'MCAP bag', 'rosbag2 layout,\nreadable without ROS',
         'pentapod_sim/analysis/bag/'),
        ('frf', 'analysis', 'FRF estimation', 'H1/H2, coherence, peaks,\nUFF58 export',
         'pentapod_sim/analysis/frf/'),
        ('ema', 'analysis', 'modal identification', 'pLSCF + LSFD,\nstability diagram',
         'pentapod_sim/analysis/ema/'),
        ('study', 'analysis', 'the study', 'every scenario at P1, P2:\nreport, tables, figures',
         'pentapod_damper/study/'),
    ]
    arrows = [
        ('config', 'fe', '', []), ('fe', 'modes', '', []), ('modes', 'plant_model', '', []),
        ('plant_model', 'plant', 'model file', []),
        ('plant', 'sources', '$y_k$ on\n' + '\n'.join(states), states),
        ('sources', 'plant', '$u_k$ on\n' + interface.force_topic('<source>'),
         [interface.force_topic('<source>')]),
        ('plant', 'recorder', 'every topic', []), ('sources', 'recorder', '', []),
        ('plant', 'live_view', '', []),
        ('recorder', 'bag', '', []), ('bag', 'frf', '', []), ('frf', 'ema', '', []),
        ('ema', 'study', '', []),
        ('plant_model', 'study', 'analytic FRFs and loop poles: the reference', []),
    ]
    return {'lanes': [list(lane[:2]) for lane in LANES],
            'boxes': [dict(zip(('key', 'lane', 'title', 'detail', 'where'), b)) for b in boxes],
            'sources': ['exciter', 'damper', 'pma', 'controller'],
            'sources_title': 'force sources: one answer per step $k$, stamped $t_k$',
            'arrows': [dict(zip(('from', 'to', 'label', 'topics'), a)) for a in arrows]}


#: (x, y) of each box's centre in figure units (0..100 wide, -2.5..56 high)
PLACES: dict[str, tuple[float, float]] = {
    'config': (11.25, 45), 'fe': (11.25, 34), 'modes': (11.25, 23), 'plant_model': (11.25, 12),
    'plant': (50, 45), 'exciter': (40.5, 26), 'damper': (59.5, 26), 'pma': (40.5, 16.5),
    'controller': (59.5, 16.5), 'live_view': (42, 4.4), 'recorder': (58, 4.4),
    'bag': (88.75, 45), 'frf': (88.75, 34), 'ema': (88.75, 23), 'study': (88.75, 12)}
#: (left, width) of each lane
LANE_SPANS = {'model': (0.5, 21.5), 'run': (24, 52), 'analysis': (78, 21.5)}
SMALL = ('recorder', 'live_view')


def _size(key: str) -> tuple[float, float]:
    return (14.0, 6.6) if key in SMALL else (17.0, 8.2)


def draw(path: Path = FIGURE) -> Path:
    """Draw the figure of :func:`spec` and write it (with the spec) to ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.patches import FancyBboxPatch
    import matplotlib.pyplot as plt

    data = spec()
    colours = {key: colour for key, _, colour in LANES}
    fig = plt.figure(figsize=(11.0, 6.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 100)
    ax.set_ylim(-2.5, 56)
    ax.axis('off')
    for key, title in data['lanes']:
        x0, width = LANE_SPANS[key]
        ax.add_patch(FancyBboxPatch((x0, -2.2), width, 57.8,
                                    boxstyle='round,pad=0,rounding_size=1.2',
                                    fc=colours[key], ec='none', alpha=0.5))
        ax.text(x0 + width / 2, 53.6, title, ha='center', va='center', fontsize=11.5,
                weight='bold', color='#333333')
    ax.add_patch(FancyBboxPatch((30, 11), 40, 22, boxstyle='round,pad=0.3',
                                fc='none', ec='#9a6b3a', ls='--', lw=1.0))
    ax.text(50, 31.9, data['sources_title'], ha='center', va='center', fontsize=9.0,
            style='italic', color='#6b4a28')
    for box in data['boxes']:
        x, y = PLACES[box['key']]
        w, h = _size(box['key'])
        user = box['key'] == 'controller'
        ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h,
                                    boxstyle='round,pad=0.3,rounding_size=0.8',
                                    fc='white', ec='#7b3fa0' if user else '#555555',
                                    lw=1.7 if user else 1.0))
        ax.text(x, y + h / 2 - 1.2, box['title'], ha='center', va='top', fontsize=10.5,
                weight='bold')
        ax.text(x, y - 0.3 if box['key'] in SMALL else y - 0.1, box['detail'], ha='center',
                va='center', fontsize=8.6, color='#333333', linespacing=1.2)
        ax.text(x, y - h / 2 + 0.8, box['where'].removeprefix('run:'), ha='center',
                va='bottom', fontsize=7.6, family='monospace', color='#1f4e79')
    _arrows(ax, data)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, metadata={'Software': None,
                                         CHUNK: json.dumps(data, sort_keys=True)})
    plt.close(fig)
    return path


#: polyline of each arrow (the last point is the arrowhead) and where its label goes
ROUTES: dict[tuple[str, str], list[tuple[float, float]]] = {
    ('config', 'fe'): [(11.25, 40.6), (11.25, 38.4)],
    ('fe', 'modes'): [(11.25, 29.6), (11.25, 27.4)],
    ('modes', 'plant_model'): [(11.25, 18.6), (11.25, 16.4)],
    ('plant_model', 'plant'): [(20.05, 12), (23, 12), (23, 45), (41.2, 45)],
    ('plant', 'sources'): [(46, 40.6), (46, 33.3)],
    ('sources', 'plant'): [(54, 33.3), (54, 40.6)],
    ('plant', 'recorder'): [(58.8, 45), (73, 45), (73, 9.4), (58, 9.4), (58, 8.0)],
    ('sources', 'recorder'): [(70.3, 22), (73, 22), (73, 9.4), (58, 9.4), (58, 8.0)],
    ('plant', 'live_view'): [(58, 9.4), (42, 9.4), (42, 8.0)],
    ('recorder', 'bag'): [(65.3, 4.4), (76.5, 4.4), (76.5, 45), (79.95, 45)],
    ('bag', 'frf'): [(88.75, 40.6), (88.75, 38.4)],
    ('frf', 'ema'): [(88.75, 29.6), (88.75, 27.4)],
    ('ema', 'study'): [(88.75, 18.6), (88.75, 16.4)],
    ('plant_model', 'study'): [(11.25, 7.6), (11.25, -1.2), (88.75, -1.2), (88.75, 7.6)],
}
#: (x, y, horizontal alignment, rotation) of an arrow's label
LABELS: dict[tuple[str, str], tuple[float, float, str, int]] = {
    ('plant', 'sources'): (45.3, 36.9, 'right', 0), ('sources', 'plant'): (54.7, 36.9, 'left', 0),
    ('plant_model', 'plant'): (22.3, 28, 'center', 90),
    ('plant', 'recorder'): (73.9, 27, 'center', 90),
    ('plant_model', 'study'): (14, -0.95, 'left', 0)}


def _arrows(ax, data: dict) -> None:
    """The arrows of the spec along their :data:`ROUTES`."""
    colour, width = '#444444', 1.1
    for arrow in data['arrows']:
        key = (arrow['from'], arrow['to'])
        points = ROUTES[key]
        for a, b in zip(points[:-2], points[1:-1]):
            ax.plot([a[0], b[0]], [a[1], b[1]], color=colour, lw=width,
                    solid_capstyle='butt')
        ax.annotate('', xy=points[-1], xytext=points[-2],
                    arrowprops={'arrowstyle': '-|>', 'color': colour, 'lw': width,
                                'shrinkA': 0, 'shrinkB': 0})
        if arrow['label']:
            x, y, align, rotation = LABELS[key]
            ax.text(x, y, arrow['label'], ha=align, va='bottom' if y < 0 else 'center',
                    fontsize=8.0, color='#222222', linespacing=1.2, rotation=rotation,
                    family='monospace' if arrow['topics'] else None)


def stored_spec(path: Path = FIGURE) -> dict:
    """The spec a drawn figure holds (its PNG text chunk), read with Pillow."""
    from PIL import Image
    with Image.open(path) as image:
        return json.loads(image.info[CHUNK])


if __name__ == '__main__':
    print(f'wrote {draw().relative_to(ROOT)}')
