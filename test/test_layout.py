"""The layout's rules, checked by walking every import of the two packages (also local ones)."""
import ast
from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('pentapod_sim', 'pentapod_damper')
#: Pipeline order: a module may import only from its own stage or earlier ones.
STAGES = [
    ('pentapod_sim.exits', 'pentapod_sim.errors', 'pentapod_sim.shutdown',
     'pentapod_sim.registry',
     'pentapod_sim.figures', 'pentapod_sim.__init__', 'pentapod_sim.schema',
     'pentapod_sim.parameters', 'pentapod_sim.reference'),
    ('pentapod_sim.paths',),
    ('pentapod_sim.fe',),
    ('pentapod_sim.modes',),
    ('pentapod_sim.plant',),
    ('pentapod_sim.sim', 'pentapod_sim.topic_layout', 'pentapod_sim.interface'),
    ('pentapod_sim.machining',),
    ('pentapod_sim.recording', 'pentapod_sim.analysis', 'pentapod_sim.scenario',
     'pentapod_sim.live'),
    ('pentapod_sim.nodes', 'pentapod_sim.cli'),
    ('pentapod_damper.laws', 'pentapod_damper.node_parameters', 'pentapod_damper.scenario_laws',
     'pentapod_damper.__init__'),
    ('pentapod_damper.nodes', 'pentapod_damper.study', 'pentapod_damper.sweep',
     'pentapod_damper.design', 'pentapod_damper.judge'),
]
#: Packages that need a ROS installation; only node modules may import them.
ROS_MODULES = ('rclpy', 'rcl_interfaces', 'builtin_interfaces', 'sensor_msgs', 'geometry_msgs',
               'rosgraph_msgs', 'std_msgs', 'launch', 'launch_ros')
MAX_LINES = 400
#: The force-source node modules; started by the dozen in a scenario, they must not load the FE
#: model code or the eigen solver (seconds of imports and memory per process for nothing).
SOURCE_NODES = ('pentapod_sim.nodes.exciter_node', 'pentapod_sim.nodes.cutting_node',
                'pentapod_sim.nodes.disturbance_node',
                'pentapod_damper.nodes.damper_node',
                'pentapod_damper.nodes.pma_node', 'pentapod_damper.nodes.example_controller')
FE_PACKAGES = ('pentapod_sim.fe', 'pentapod_sim.modes')


def _modules():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob('*.py')):
            name = '.'.join(path.relative_to(ROOT).with_suffix('').parts)
            yield name, path


def _imports(path: Path):
    """(line, imported module) of every import statement, at any depth."""
    tree = ast.parse(path.read_text(encoding='utf-8'))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.lineno, node.module
            for alias in node.names:                    # from pentapod_sim import fe
                yield node.lineno, f'{node.module}.{alias.name}'


def _stage(module: str) -> int | None:
    for rank, prefixes in enumerate(STAGES):
        if any(module == p or module.startswith(p + '.') for p in prefixes):
            return rank
    return None


def test_every_module_has_a_stage():
    assert [m for m, _ in _modules() if _stage(m) is None] == []


@pytest.mark.parametrize('module,path', list(_modules()), ids=lambda v: str(v))
def test_imports_run_one_way(module, path):
    """Nothing imports a later stage; pentapod_sim never imports pentapod_damper."""
    own = _stage(module)
    bad = []
    for line, target in _imports(path):
        if not target.startswith(PACKAGES):
            continue
        if module.startswith('pentapod_sim') and target.startswith('pentapod_damper'):
            bad.append(f'{path.name}:{line} imports {target} (pentapod_sim -> pentapod_damper)')
        rank = _stage(target)
        if rank is not None and rank > own:
            bad.append(f'{path.name}:{line} imports {target} (a later stage)')
    assert bad == []


@pytest.mark.parametrize('module,path', list(_modules()), ids=lambda v: str(v))
def test_ros_free_core(module, path):
    """Only node modules (``*.nodes.*``) import rclpy or message packages."""
    if '.nodes.' in module or module.endswith('.nodes'):
        return
    bad = [f'{path.name}:{line} imports {target}' for line, target in _imports(path)
           if target.split('.')[0] in ROS_MODULES]
    assert bad == []


def test_no_file_over_the_size_limit():
    big = {str(p.relative_to(ROOT)): n for _, p in _modules()
           if (n := len(p.read_text(encoding='utf-8').splitlines())) > MAX_LINES}
    assert big == {}


def test_the_rule_catches_a_violation(tmp_path):
    """The import walker sees a function-local import of a later stage."""
    path = tmp_path / 'x.py'
    path.write_text('def f():\n    from pentapod_damper.laws import tcp_damper\n')
    assert (2, 'pentapod_damper.laws') in list(_imports(path))
    assert _stage('pentapod_damper.laws') > _stage('pentapod_sim.plant.model')


def _loaded_by(module: str) -> list[str]:
    """Every module in ``sys.modules`` after importing ``module`` in a fresh interpreter."""
    code = f'import sys\nimport {module}\nprint("\\n".join(sorted(sys.modules)))'
    done = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def _fe_modules(loaded: list[str]) -> list[str]:
    return [m for m in loaded if any(m == p or m.startswith(p + '.') for p in FE_PACKAGES)]


@pytest.mark.parametrize('module', SOURCE_NODES)
def test_source_nodes_load_no_fe_code(module):
    """A force-source node imported on its own loads nothing of ``fe/`` or ``modes/``."""
    loaded = _loaded_by(module)
    assert module in loaded
    assert _fe_modules(loaded) == []


def test_the_source_rule_sees_the_fe_code_the_plant_loads():
    """The same check on the plant node (which builds models from the FE model) finds it."""
    assert 'pentapod_sim.fe.assembly' in _fe_modules(_loaded_by('pentapod_sim.nodes.plant_node'))
