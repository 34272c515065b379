"""
Run the paper's damping study end to end: ``python -m pentapod_damper.study [options]``.

Pieces (:mod:`pentapod_damper.study.pieces`): reduced plant per position, analytic FRFs and
loop poles of every scenario, one recorded lockstep run per position and scenario, PMA
step-response runs, damping runs, bending damper comparison, figures; then the report
(out/study/report.md with PNG figures and CSV tables) and a short summary. Independent pieces
run side by side (``--jobs``, default one per CPU), each testbed run on its own ROS domain;
one progress line per finished piece. A failed piece stops the study with a one-line error;
Ctrl-C stops the running runs and exits with 130.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
import signal
import sys
import time

import numpy as np

from pentapod_damper.study import bending, pieces
from pentapod_damper.study.config import load_study_config, StudyConfig
from pentapod_damper.study.pieces import pma_results  # noqa: F401  (test_docs uses it here)
from pentapod_damper.study.report import struts12_share, StudyResults, summary_rows, write_report
from pentapod_damper.study.schedule import Interrupted, run_pieces, Schedule
from pentapod_sim import shutdown
from pentapod_sim.cli import CommandParser
from pentapod_sim.errors import BagError, ConfigError, RunError
from pentapod_sim.scenario.domain import DOMAIN_VAR, user_domain

LOG = logging.getLogger('pentapod_damper.study')


def _say(msg: str) -> None:
    print(f'[study {time.strftime("%H:%M:%S")}] {msg}', flush=True)


def default_jobs() -> int:
    """Pieces run at once by default: one per CPU this process may use."""
    return max(1, len(os.sched_getaffinity(0)))


def run_study(res: StudyResults, cfg: StudyConfig, runs: bool, jobs: int) -> Schedule:
    """
    Every piece of the study, ``jobs`` at a time; ``res`` is filled in the study file's order.

    Testbed runs each reserve a free ROS domain; with ``ROS_DOMAIN_ID`` set (the user's
    choice of one domain) they run one at a time on it.
    """
    extra: dict = {}
    lanes = {pieces.ROS_LANE: 1} if user_domain(os.environ) is not None else {}
    if lanes and runs and jobs > 1:
        _say(f'{DOMAIN_VAR} is set: the testbed runs go one at a time on domain '
             f'{os.environ[DOMAIN_VAR]} (unset it to run them side by side)')
    schedule = run_pieces(pieces.study_pieces(res, cfg, runs, extra), jobs, _say,
                          lanes=lanes)
    pieces.in_order(res, cfg, extra)
    for stage, (span, busy, count) in schedule.stages().items():
        # busy: summed time of the pieces (what the stage took one piece at a time); span:
        # first start to last end (the pieces of other stages ran in between)
        res.timings[f'{stage}: {count} pieces, busy'] = busy
        res.timings[f'{stage}: first start to last end'] = span
        _say(f'{stage}: {count} pieces, {busy:.1f} s busy, {span:.1f} s from first start to '
             'last end')
    return schedule


def _print_summary(res: StudyResults, report: Path) -> None:
    print('\nSummary (analytic peak reduction; testbed check against the sampled loop)')
    print(f'{"pos":4} {"scenario":18} {"peak um/N":>10} {"peak red.":>9} {"rms red.":>8} '
          f'{"meas. dev dB":>12} {"steps/s":>8}')
    for r in summary_rows(res):
        print(f'{r["position"]:4} {r["scenario"]:18} {r["peak_um_per_N"]:10.4f} '
              f'{r["peak_reduction"]:9.2f} {r["rms_reduction"]:8.2f} '
              f'{r.get("deviation_db", float("nan")):12.2f} {r.get("steps_per_s", 0):8.0f}')
    for r in struts12_share(res):
        print(f'struts 1-2 achieve {r["peak_share"]:.0%} (peak) / {r["rms_share"]:.0%} (RMS) '
              f'of the all-struts improvement at {r["position"]}')
    for r in res.bending_models:
        print(f'{r["position"]} {r["model"]:10} optimum {r["optimal_gain"]:9.4g} '
              f'{r["gain_unit"]}: {r["reduction_all_opt"]:.2f}x, struts 1-2 '
              f'{r["peak_share_12_opt"]:.0%} / {r["rms_share_12_opt"]:.0%}; at b = '
              f'{bending.PAPER_GAIN:g}: {r["reduction_all_paper"]:.2f}x, struts 1-2 '
              f'{r["peak_share_12_paper"]:.0%} / {r["rms_share_12_paper"]:.0%}')
    print(f'report: {report}')


def main(argv: list[str] | None = None) -> int:
    """Run the study: 0 on success, 1 with a one-line error on a failure, 128 + n on signal n."""
    parser = CommandParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--config', help='study YAML (default config/study.yaml)')
    parser.add_argument('--out', default='out/study', help='output folder')
    parser.add_argument('--duration', type=float, help='excited time per run [s]')
    parser.add_argument('--positions', help='comma-separated positions, e.g. P1,P2')
    parser.add_argument('--analytic-only', action='store_true',
                        help='skip the testbed runs (no ROS): analytic figures only')
    parser.add_argument('--jobs', type=int, default=default_jobs(),
                        help='pieces (model builds, analytic FRFs, testbed runs) run at once '
                        '(default: one per CPU, here %(default)s)')
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f'--jobs must be >= 1, got {args.jobs}')
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    t_start = time.perf_counter()
    handlers = {sig: signal.getsignal(sig) for sig in shutdown.STOP_SIGNALS}
    shutdown.install()
    try:
        positions = tuple(args.positions.split(',')) if args.positions else None
        cfg = load_study_config(args.config, duration=args.duration, positions=positions)
        if cfg.step_position not in cfg.positions:
            raise ConfigError(f'step_response.position = {cfg.step_position} is not among the '
                              f'positions {", ".join(cfg.positions)}: add it (--positions) or '
                              'set step_response.position in the study file')
        res = StudyResults(cfg, np.linspace(*cfg.freq_grid[:2], int(cfg.freq_grid[2])))
        res.out_dir = Path(args.out)
        res.out_dir.mkdir(parents=True, exist_ok=True)
        run_study(res, cfg, not args.analytic_only, args.jobs)
        res.timings['total'] = time.perf_counter() - t_start
        report = write_report(res, res.out_dir)
    except (ConfigError, RunError, BagError) as err:
        print(f'study failed: {err}', file=sys.stderr)
        return 1
    except Interrupted as err:
        print(f'study stopped: {err}', file=sys.stderr)
        return err.code
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    _print_summary(res, report)
    _say(f'done in {time.perf_counter() - t_start:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
