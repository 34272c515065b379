"""
The study's machining stages on a small modal model: lobes, the summary's gain, recorded cuts.

Two TCP modes (150 and 170 Hz, 4 and 5 % damping) so that a cut settles or chatters within a
second; the study's own settings (sample rate 3 kHz, its operations). The stages are the
functions the study's graph calls (pentapod_damper.study.machining).
"""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from pentapod_damper.laws import tcp_damper
from pentapod_damper.study import machining
from pentapod_damper.study.config import load_study_config
from pentapod_damper.study.records import PositionModel, StudyResults
from pentapod_damper.study.schedule import study_graph
from pentapod_damper.study.tables import _depth_gain
from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.lobes import milling_limit
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.machining.sampled_tcp import sampled_tcp_frf
from pentapod_sim.machining.tcp_frf import tcp_plant, TcpMode

PLANT = tcp_plant([TcpMode(150.0, 0.04, 4e6, (1.0, 0.3)), TcpMode(170.0, 0.05, 5e6, (-0.3, 1.0))])


def _setup(tmp_path):
    cfg = load_study_config(positions=('P1',), scenarios=('baseline', 'tcp_damping'))
    model = PositionModel('P1', PLANT, PLANT.save(tmp_path / 'model.npz'), '')
    return cfg, model


def test_lobes_stage_and_the_summarys_stable_depth_gain(tmp_path):
    """The stage's minimum depth is milling_limit's on the sampled FRF; the gain their ratio."""
    cfg, model = _setup(tmp_path)
    damper = tcp_damper(['x', 'y'], 400.0, dt=cfg.dt)
    found = {}
    for name, laws in (('baseline', []), ('tcp_damping', [damper])):
        found['P1', name] = machining.scenario_lobes(cfg, model,
                                                     SimpleNamespace(name=name, laws=laws))
    table = load_machining()
    for (_, name), rec in found.items():
        laws = [] if name == 'baseline' else [damper]
        frf = sampled_tcp_frf(PLANT, laws, cfg.dt, 1.0, 1000.0).frf    # independent of the stage
        for op in cfg.machining_operations:
            want = milling_limit(frf, table.milling_cut(op)).minimum().depth
            assert rec.min_depth(op) == pytest.approx(want, rel=1e-9)
    res = StudyResults(cfg, np.zeros(1), lobes=found)
    gain = _depth_gain(res, 'P1', 'tcp_damping')
    op = cfg.machining_operations[0]
    assert gain == pytest.approx(found['P1', 'tcp_damping'].min_depth(op)
                                 / found['P1', 'baseline'].min_depth(op))
    assert gain > 1.2 and _depth_gain(res, 'P1', 'baseline') == 1.0
    rows = machining.lobes_table(cfg, found).rows
    assert [r['scenario'] for r in rows] == ['baseline', 'tcp_damping']
    assert rows[1][f'{op}_stable_depth_gain'] == pytest.approx(gain)
    figs = machining.lobe_figures(cfg, tmp_path, 'P1', {k[1]: v for k, v in found.items()})
    assert all(p.is_file() for p in figs.paths.values()) and len(figs.paths) == 2


@pytest.mark.ros
@pytest.mark.slow
def test_cutting_stage_records_a_stable_and_a_chattering_cut(tmp_path):
    """The study's cutting stage at its 3 kHz: 0.8x stable and 1.2x chatter, from the bags."""
    cfg, model = _setup(tmp_path)
    analytic = SimpleNamespace(name='baseline', laws=[])
    lobes = machining.scenario_lobes(cfg, model, analytic)
    check = machining.cutting_check(cfg, tmp_path, model, analytic, lobes)
    assert [c.run.factor for c in check.cuts] == [0.8, 1.2]
    assert [c.verdict.verdict for c in check.cuts] == ['stable', 'chatter'], check.describe()
    assert check.speed <= 60.0 / (4 * 50 * cfg.dt)                # >= 50 steps per tooth
    rows = machining.cuts_table([check]).rows
    assert [r['as_predicted'] for r in rows] == [True, True]
    assert rows[1]['depth_mm'] == pytest.approx(1.2 * check.depth * 1e3)
    # the run was at the study's sample rate
    doc = yaml.safe_load((tmp_path / 'runs' / 'P1_baseline_cut_0_8x.yaml').read_text())
    assert {doc[n]['ros__parameters']['sample_rate'] for n in ('plant', 'cutting')} == {3000.0}


def test_the_study_file_names_real_operations_and_study_scenarios():
    with pytest.raises(ConfigError, match="machining.operations.0.*'aluminium_half_down'"):
        load_study_config(machining_operations=('aluminium_half_dwn',))
    with pytest.raises(ConfigError, match=r"machining.cutting_runs\[0\].*'tcp_damping'"):
        load_study_config(cutting_runs=('tcp_dampng',))
    # a study of fewer scenarios cuts those it has (as the damping runs)
    cfg = load_study_config(scenarios=('baseline',), cutting_runs=('tcp_damping',))
    graph = study_graph(cfg, Path('unused'), np.linspace(1.0, 10.0, 3))
    assert not graph.cutting and list(graph.lobes) == [('P1', 'baseline'), ('P2', 'baseline')]
    graph = study_graph(load_study_config(), Path('unused'), np.linspace(1.0, 10.0, 3))
    assert sorted(graph.cutting) == [('P1', 'tcp_damping'), ('P2', 'tcp_damping')]
