"""
The probes of issue 25 ("Runs you can trust") on the current tree: how each attack or fault ends.

Each probe makes its attack or fault happen on a real run (the scenario runner, every node its
own process, on a free ROS domain with LOCALHOST discovery): a participant forging the plant's
state before and during the run, forged empty / partial / second force answers, SIGSTOP and
SIGKILL of the plant and of the recorder, a gain set to 1e9 mid-run, ``sample_rate`` 1e6,
``--model-file /etc/passwd``, and the sockets of a default run. It prints a markdown table:
probe, what the issue reported before the fix, the runner's exit code, the line that names the
end, and what the bag holds (rosbags and the mcap library opening it, the recorder's own
unique/expected count; a bag without a footer also after ``analyze recover``). No timing is
asserted: it is a record, not a test (test/test_writers.py, test_run_ends.py,
test_recorder_spoofed.py ... are the tests).

    PYTHONPATH=. python bench/integrity_probes.py [--only NAME ...] [--write docs/integrity.md]

``--write`` replaces the table between the generation markers of that file. Takes about 15
minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import tempfile
import time
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))   # the tests' scenarios, runner handle and spoofer

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from pentapod_sim.interface import TCP_STATE  # noqa: E402
from pentapod_sim.reference import replace_section  # noqa: E402
from pentapod_sim.scenario.files import dump_params  # noqa: E402
from pentapod_sim.scenario.network import process_sockets  # noqa: E402

MARK = 'integrity probes'
STEPS = 16000           # a run that ends by itself, long enough for a spoofer to join


class Probe:
    """One probe's folder, its runner and what it found."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.run = None
        self.fake: subprocess.Popen | None = None
        self.notes: list[str] = []
        self.message: str | None = None     # what names the end, if not a line of the log

    def start(self, path: Path, *args: str):
        from test_stopping import Runner
        self.run = Runner(path, self.folder, *args)
        return self.run

    def child(self, needle: str) -> int:
        return next(p for p, cmd in self.run.children().items() if needle in cmd)

    def wait(self, timeout: float = 400.0) -> int | None:
        try:
            return self.run.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.notes.append(f'still running after {timeout:.0f} s: killed')
            self.run.kill_all()
            return None
        finally:
            if self.fake is not None:
                self.fake.kill()
                self.fake.wait()


def with_params(path: Path, section: str, **values) -> Path:
    doc = yaml.safe_load(path.read_text())
    doc[section]['ros__parameters'].update(values)
    path.write_text(dump_params(doc))
    return path


def forged_force_steps(trace: Path, limit: float = 1.0e4) -> str:
    """Steps of the plant's trace with a TCP force above ``limit`` N (the forgeries' 100 kN)."""
    if not trace.exists():
        return 'no trace'
    data = np.load(trace)
    n = int(np.count_nonzero(np.abs(data['u']).max(axis=1) > limit))
    return f'{n} of {int(data["steps_run"])} steps with > 10 kN applied'


# ---- the probes: each returns the runner's exit code ----------------------------------------

def spoofed_state(when: str) -> Callable[[Probe], int | None]:
    def probe(p: Probe) -> int | None:
        from test_stopping import RATE, scenario
        from test_writers import spoofer
        path = scenario(p.folder, steps=STEPS)
        if when == 'before':
            p.fake = spoofer(RATE, 'free')
            time.sleep(2.0)
        run = p.start(path)
        if when == 'during':
            run.wait_for('lockstep run of')
            time.sleep(1.0)
            p.fake = spoofer(RATE)
        code = p.wait()
        p.notes.append(forged_force_steps(p.folder / 'trace.npz'))
        return code
    return probe


def forged_answer(mode: str, during: bool = False) -> Callable[[Probe], int | None]:
    def probe(p: Probe) -> int | None:
        from test_stopping import RATE, scenario
        from test_writers import spoofer
        run = p.start(scenario(p.folder, steps=STEPS))
        if during:
            run.wait_for('lockstep run of')
            time.sleep(1.0)
        p.fake = spoofer(RATE, mode)
        code = p.wait()
        p.notes.append(forged_force_steps(p.folder / 'trace.npz'))
        return code
    return probe


def forged_recorded_topic(p: Probe) -> int | None:
    from test_stopping import RATE, scenario
    from test_writers import spoofer
    run = p.start(scenario(p.folder, steps=STEPS))
    run.wait_for('lockstep run of')
    p.fake = spoofer(RATE, 'excitation')
    return p.wait()


def signal_to(node: str, sig: int, timing: str = 'lockstep',
              record: bool = True) -> Callable[[Probe], int | None]:
    def probe(p: Probe) -> int | None:
        from test_stopping import LONG, scenario
        path = scenario(p.folder, steps=LONG, record=record, timing=timing)
        run = p.start(with_params(path, '/**', plant_stall_timeout=5.0))
        run.wait_for(f'{timing} run of')
        time.sleep(2.0)
        pid = p.child(f'{node}_node')
        os.kill(pid, sig)
        try:
            return p.wait(300.0)
        finally:
            for cleanup in (signal.SIGCONT, signal.SIGKILL):
                try:
                    os.kill(pid, cleanup)
                except ProcessLookupError:
                    pass
    return probe


def gain_mid_run(p: Probe) -> int | None:
    from test_midrun_params import set_gain
    from test_stopping import scenario
    run = p.start(scenario(p.folder, steps=STEPS))
    run.wait_for('lockstep run of')
    time.sleep(1.0)
    p.notes.append('set accepted' if set_gain('damper', 1.0e9) else 'set refused')
    code = p.wait()
    text = p.run.text()
    for needle in (r'parameter tcp_gain changed during the run: [^,]*, acting from step \d+',
                   r'truncation check \(loop_check = \w+\) of the new model of damper'):
        found = re.search(needle, text)
        p.notes.append(found.group(0) if found else f'no line {needle!r}')
    return code


def huge_sample_rate(p: Probe) -> int | None:
    from test_check_bounds import real_scenario
    p.start(real_scenario(p.folder, 1.0e6), '--timeout', '300')
    return p.wait()


def model_file_passwd(p: Probe) -> int | None:
    from test_stopping import scenario
    p.start(scenario(p.folder, steps=100, record=False), '--model-file', '/etc/passwd')
    return p.wait()


def sockets(p: Probe) -> int | None:
    from test_network import descendants
    from test_stopping import LONG, scenario
    run = p.start(scenario(p.folder, steps=LONG))
    run.wait_for('lockstep run of')
    time.sleep(2.0)
    pids = [run.proc.pid, *descendants(run.proc.pid)]
    found = [s for pid in pids for s in process_sockets(pid)]
    outside = [str(s) for s in found if not s.loopback]
    p.message = (f'{len(found)} sockets of {len(pids)} processes mid-run, {len(outside)} '
                 'outside 127.0.0.0/8' + (f': {outside}' if outside else '') +
                 '; then SIGINT to the runner')
    run.proc.send_signal(signal.SIGINT)
    return p.wait(120.0)


#: name -> (what issue 25 reported before the fix, the probe)
PROBES: dict[str, tuple[str, Callable[[Probe], int | None]]] = {
    'state spoofed before the run': (
        'not refused (the check was by node name)', spoofed_state('before')),
    'state spoofed during the run (one step ahead)': (
        'exit 0; ~100 kN on 8388 of 15000 steps; recorder "none missing"',
        spoofed_state('during')),
    'empty force answer at the right stamp': (
        'accepted, displaced the real answer, no warning', forged_answer('empty')),
    'partial force answer at the right stamp': (
        'accepted, displaced the real answer, no warning', forged_answer('partial')),
    'second force writer mid-run (100 kN)': (
        'refused by node name after 26-60 steps of 100 kN', forged_answer('force', True)),
    'recorded topic forged mid-run (excitation)': (
        'recorder: "none missing"', forged_recorded_topic),
    'SIGSTOP plant (lockstep)': (
        'noticed by nothing; hangs until --timeout (3600 s)', signal_to('plant', signal.SIGSTOP)),
    'SIGSTOP plant (realtime)': (
        'noticed by nothing', signal_to('plant', signal.SIGSTOP, 'realtime', record=False)),
    'SIGKILL plant': ('exit 247 (undocumented)', signal_to('plant', signal.SIGKILL)),
    'SIGSTOP recorder': (
        'exit 0 after 152 s, 78 % of the run missing', signal_to('recorder', signal.SIGSTOP)),
    'SIGKILL recorder': (
        'bag without footer: rosbags "File end magic is invalid"',
        signal_to('recorder', signal.SIGKILL)),
    'tcp_gain 1e9 mid-run': (
        'accepted, logged by no node, no truncation check', gain_mid_run),
    'sample_rate 1e6': (
        'truncation check > 85 s before step 0, ignores SIGINT', huge_sample_rate),
    'model_file /etc/passwd': ("numpy's allow_pickle message", model_file_passwd),
    'sockets of a default run (ss)': (
        '0.0.0.0 UDP 7000-7004, 52410-52419, the external address', sockets),
}

#: lines that name how a run ended, best first
NAMING = (r'^error: .*', r'^ERROR recording failed.*', r'^ERROR the plant .* stalled.*',
          r'^ERROR node .*', r'^ERROR stopping the plant.*',
          r'\[recorder\]: unique/expected steps: .*',
          r'\[plant\]: (finished|stopped by|error).*', r'\[(damper|plant)\]: parameter .*')


def naming_line(text: str, trace: Path) -> str:
    """The plant's own end if it was an error (its trace says), else the first line naming it."""
    if trace.exists():
        end = str(np.load(trace)['end'])
        if end.startswith('error: '):
            return 'plant: ' + (end if len(end) <= 220 else end[:217] + '...')
    lines = text.splitlines()
    for pattern in NAMING:
        found = [x for x in lines if re.search(pattern, x)]
        if found:
            line = re.sub(r'^\[\w+\] \[[\d.]+\] ', '', found[0])
            return line if len(line) <= 220 else line[:217] + '...'
    return '(nothing named)'


def bag_text(folder: Path) -> str:
    """What the run's bag holds, as rosbags and the mcap library read it (recovered if need)."""
    bag = folder / 'bags' / 'run'
    if not bag.exists():
        return 'no bag (not recorded)'
    found = read_bag(bag)
    if 'rosbags refuses' in found:
        from pentapod_sim.recording.recover import recover_bag
        try:
            recovery = recover_bag(bag)
            found += f'; `analyze recover` -> {read_bag(Path(recovery.output))}'
        except Exception as err:          # a probe reports, it does not stop
            found += f'; analyze recover failed: {err}'
    return found


def read_bag(bag: Path) -> str:
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader
    parts = []
    try:
        with AnyReader([bag]) as reader:
            conns = [c for c in reader.connections if c.topic == TCP_STATE]
            n = sum(1 for _ in reader.messages(connections=conns))
        parts.append(f'rosbags opens it: {n} tcp_state')
    except Exception as err:
        parts.append(f'rosbags refuses ({str(err).splitlines()[0][:80]})')
    try:
        with open(next(bag.glob('*.mcap')), 'rb') as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        total = summary.statistics.message_count if summary and summary.statistics else '?'
        parts.append(f'mcap opens it: {total} messages')
        record = meta.get('pentapod_recording')
        if record:
            bad = [k for k in ('missing', 'conflicting', 'foreign') if record.get(k, '{}') != '{}']
            parts.append(f'recorder report ({record.get("run_state")}): '
                         + (', '.join(bad) if bad else 'nothing missing, conflicting or foreign'))
    except Exception as err:
        parts.append(f'mcap refuses ({str(err).splitlines()[0][:80]})')
    return '; '.join(parts)


def cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0], allow_abbrev=False)
    parser.add_argument('--only', nargs='+', metavar='NAME', help='probes whose name has NAME')
    parser.add_argument('--write', type=Path, help='markdown file to put the table into')
    parser.add_argument('--keep', type=Path, metavar='DIR',
                        help="keep each probe's files (logs, bag, trace) in DIR/<probe>")
    args = parser.parse_args(argv)
    # one reserved domain for the runs and the spoofers (the runner would pick its own)
    from pentapod_sim.scenario.domain import isolation
    changes, lease = isolation(os.environ)
    os.environ.update(changes)
    try:
        return probe_all(args)
    finally:
        if lease is not None:
            lease.release()


def probe_all(args) -> int:
    rows = ['| probe | before (issue 25) | exit | message | bag |', '|---|---|---|---|---|']
    for name, (before, probe) in PROBES.items():
        if args.only and not any(o in name for o in args.only):
            continue
        print(f'probe: {name}', file=sys.stderr, flush=True)
        with tempfile.TemporaryDirectory(prefix='probe_') as tmp:
            if args.keep:
                tmp = str(args.keep / re.sub(r'\W+', '_', name).strip('_'))
                Path(tmp).mkdir(parents=True, exist_ok=True)
            p = Probe(Path(tmp))
            code = probe(p)
            text = p.run.text() if p.run else ''
            message = (p.message or naming_line(text, Path(tmp) / 'trace.npz')).replace(
                f'{tmp}/', '')                  # no machine paths in the table
            if p.notes:
                message += ' (' + '; '.join(p.notes) + ')'
            row = (name, before, 'none' if code is None else str(code), message,
                   bag_text(Path(tmp)))
        rows.append('| ' + ' | '.join(cell(c) for c in row) + ' |')
        print(rows[-1], flush=True)
    table = '\n'.join(rows) + '\n'
    print(table)
    if args.write:
        args.write.write_text(replace_section(args.write.read_text(), MARK, table))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
