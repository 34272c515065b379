"""
Start a whole scenario from a ROS parameter file: every node its own process, like ros2 run.

A scenario file (config/scenarios/*.yaml) is an ordinary ROS 2 parameter file: one
``<node_name>: ros__parameters:`` section per node plus an optional ``/**`` section shared by
all (e.g. ``sample_rate``). A node runs the node kind its name starts with
(:data:`pentapod_sim.registry.NODES`: ``plant``, ``exciter``, ``damper*``, ``pma*``,
``example_controller*``, ``recorder*``, ``live_view*``) or the class its section names
(``node_class: module:Class``, run by :mod:`pentapod_sim.nodes.component`). The runner checks
the file (:func:`pentapod_sim.scenario.files.read_scenario`), writes the run's one parameter
file from the checked values, starts the sources first, then the plant, waits for the plant to
end, stops the others with SIGINT (SIGKILL after a grace period; a source that saw the
plant's run end says so and exits 0) and returns the plant's exit code, or the code of what
else went wrong (:mod:`pentapod_sim.exits`, docs/interface.md "Stopping and exit codes"): 3 if
a recorder did not close its bag complete (it failed, was killed, or stayed stopped), naming
it; 4 if a source saw the plant stall (the plant is then stopped at once); 1 if another node
failed (also when the plant then had to be stopped); 5 if the plant did not end within
``--timeout``; 128 + N for a plant killed by signal N.
launch/testbed.launch.py uses the same parser.

SIGINT, SIGTERM or SIGHUP to the runner is forwarded to every node; the nodes finish their
step, write their files and exit with 128 + the signal number, and so does the runner, after
removing its temporary files. Each node gets SIGTERM from the kernel if the runner itself dies
(``PR_SET_PDEATHSIG``), so no node outlives it. A node that dies is named with how it ended.
"""
from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

from pentapod_sim import exits, shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.registry import RECORDER
from pentapod_sim.scenario.domain import DOMAIN_VAR, isolated_env, RANGE_VAR
from pentapod_sim.scenario.files import read_scenario, resolve, Scenario, ScenarioNode
from pentapod_sim.scenario.warm_start import WarmRun, WarmStarter

LOG = logging.getLogger(__name__)

#: A node's process: started fresh, or forked warm (a composed run)
Proc = subprocess.Popen | WarmRun

#: Wall time [s] the plant gets to end by itself after another node died.
EARLY_EXIT_GRACE = 10.0
#: Module of a composed run (every node in one process).
COMPOSED_MODULE = 'pentapod_sim.nodes.composed'


def node_command(node: ScenarioNode, params_file: Path) -> list[str]:
    """Command line of one node's process (``python -m module ... --ros-args ...``)."""
    cmd = [sys.executable, '-m', node.module]
    if node.kind is None:                       # a user's class, run by the component host
        cmd.append(node.node_class)
    return cmd + ['--ros-args', '-r', f'__node:={node.name}', '--params-file', str(params_file)]


def composed_command(params_file: Path) -> list[str]:
    """Command line of a composed run: every node in one process."""
    return [sys.executable, '-m', COMPOSED_MODULE, str(params_file)]


def stop(procs: dict[str, Proc], grace: float = 5.0,
         graces: dict[str, float] | None = None) -> dict[str, int | None]:
    """
    SIGINT every running process, SIGKILL (named) those still alive after ``grace`` s.

    ``graces`` gives some processes longer (a recorder draining the last steps: a killed one
    leaves a bag without footer). Returns the exit codes of the processes it stopped.
    """
    running = [name for name, proc in procs.items() if proc.poll() is None]
    for name in running:
        procs[name].send_signal(signal.SIGINT)
        procs[name].send_signal(signal.SIGCONT)   # a stopped process ends cleanly too
    start = time.monotonic()
    for name, proc in procs.items():
        limit = (graces or {}).get(name, grace)
        try:
            proc.wait(timeout=max(0.1, start + limit - time.monotonic()))
        except subprocess.TimeoutExpired:
            LOG.error('node %s did not stop within %.0f s of SIGINT; killing it', name, limit)
            proc.kill()
            proc.wait()
    return {name: procs[name].poll() for name in running}


def drain_recorders(scenario: Scenario, procs: dict[str, Proc],
                    limit: float = 120.0) -> None:
    """
    Let the recorders write every step before the run is stopped.

    A recorder with ``stop_at_run_end`` (the default) closes its bag and exits by itself once
    it holds the last step the plant announced on every per-step topic (or ``drain_timeout``
    s after the announcement); the sources must live until then, since the messages a stalled
    recorder has not fetched yet are in their publishers' histories. After ``limit`` seconds
    (at least the recorder's ``drain_timeout`` + 10 s) it is stopped like the others (its bag
    is complete then; it holds what arrived).
    """
    waiting = [n for n in scenario.of_role(RECORDER)
               if getattr(n.params, 'stop_at_run_end', False)]
    end = time.monotonic() + max([limit] + [n.params.drain_timeout + 10.0 for n in waiting])
    for node in waiting:
        proc = procs[node.name]
        while proc.poll() is None and time.monotonic() < end:
            if stopped_for(proc, STOPPED_LIMIT):
                LOG.error('recorder %s is stopped (SIGSTOP or a debugger) and did not '
                          'continue within %.0f s; killing it: its bag is incomplete',
                          node.name, STOPPED_LIMIT)
                proc.kill()
                break
            time.sleep(0.1)
        if proc.poll() is None:
            LOG.warning('recorder %s still busy after the plant ended; stopping it', node.name)


#: Wall time [s] a recorder may stay stopped (SIGSTOP) after the plant ended before the runner
#: gives its recording up.
STOPPED_LIMIT = 5.0
_stopped_since: dict[int, float] = {}


def stopped_for(proc: Proc, limit: float) -> bool:
    """True once process ``proc`` has been stopped (state T, /proc) for ``limit`` s."""
    try:
        state = Path(f'/proc/{proc.pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    if state not in ('T', 't'):
        _stopped_since.pop(proc.pid, None)
        return False
    return time.monotonic() - _stopped_since.setdefault(proc.pid, time.monotonic()) >= limit


def run_scenario(scenario: str | Path | Scenario, plant_overrides: dict, timeout: float,
                 env: dict | None = None, log_dir: Path | None = None,
                 composed: bool = False, warm: WarmStarter | None = None,
                 params_file: Path | None = None) -> int:
    """
    Start the nodes of a scenario, wait for the plant, stop the rest; return exit code.

    ``scenario`` is a file, a shipped scenario's name or a :class:`Scenario` (typed values,
    e.g. the study's); ``plant_overrides`` change plant parameters (checked). The run's one
    parameter file is written from the typed values to ``params_file`` (default: a temporary
    file): every node process reads its section of it, a composed run reads it once and hands
    each node its values as parameter overrides.

    The nodes run isolated (:mod:`pentapod_sim.scenario.domain`): with localhost-only
    discovery and on a free ROS domain reserved until they have been stopped, unless ``env``
    (default ``os.environ``) sets ``ROS_AUTOMATIC_DISCOVERY_RANGE`` or ``ROS_DOMAIN_ID``.
    With ``log_dir`` each node's stdout and stderr go to ``log_dir/<node>.log`` instead of
    this process's terminal. ``composed`` runs every node in one process on one executor
    (:mod:`pentapod_sim.nodes.composed`), forked from ``warm`` if given
    (:mod:`pentapod_sim.scenario.warm_start`).
    """
    checked = read_scenario(scenario)             # a mistake is named before anything starts
    if plant_overrides:
        checked = checked.with_params(checked.plant.name, **plant_overrides)
    with isolated_env(env) as run_env:
        LOG.info('%s=%s, %s=%s', DOMAIN_VAR, run_env.get(DOMAIN_VAR),
                 RANGE_VAR, run_env.get(RANGE_VAR, '(unset)'))
        return _run_nodes(checked, timeout, run_env, log_dir, composed, warm, params_file)


describe_exit = exits.describe


def _plant_grace(scenario: Scenario) -> float:
    """Wall time [s] a plant may need to notice a dead source and end by itself."""
    params = scenario.plant.params
    return float(params.source_timeout + params.ack_timeout + EARLY_EXIT_GRACE)


def _start(command: list[str], env: dict, out) -> subprocess.Popen:
    """Start one node; it gets SIGTERM if this process dies (no orphans)."""
    return subprocess.Popen(command, env=env, stdout=out,
                            stderr=subprocess.STDOUT if out else None,
                            preexec_fn=shutdown.die_with_parent)


def _run_nodes(scenario: Scenario, timeout: float, env: dict, log_dir: Path | None,
               composed: bool = False, warm: WarmStarter | None = None,
               params_file: Path | None = None) -> int:
    """Body of :func:`run_scenario`, in the environment ``env``."""
    procs: dict[str, Proc] = {}
    logs: list = []
    forwarded = False
    code: int | None = None
    cause: str | None = None          # why the runner stopped the plant: 'stalled', 'recording'
    tmp = tempfile.TemporaryDirectory(prefix='pentapod_scenario_')
    try:
        path = scenario.write(params_file or Path(tmp.name) / 'parameters.yaml')
        commands = ({'composition': composed_command(path)} if composed else
                    {n.name: node_command(n, path) for n in scenario.nodes})
        for name, command in commands.items():     # the plant (or composition) last
            LOG.info('starting %s (%s)', name, ' '.join(command[1:4]))
            log = None if log_dir is None else Path(log_dir) / f'{name}.log'
            if log is not None:
                log.parent.mkdir(parents=True, exist_ok=True)
            if composed and warm is not None:
                procs[name] = warm.start(command[1:], env, log)
                continue
            out = None if log is None else open(log, 'w')  # noqa: SIM115
            if out is not None:
                logs.append(out)
            procs[name] = _start(command, env, out)
        plant = procs[list(commands)[-1]]
        end = time.monotonic() + timeout
        reported: set = set()
        recorders = {n.name for n in scenario.of_role(RECORDER)} & set(procs)
        while plant.poll() is None:
            if shutdown.requested() and not forwarded:
                # the nodes finish their step, write their files and exit by themselves
                _forward(procs, shutdown.signal_name())
                forwarded = True
                end = min(end, time.monotonic() + _plant_grace(scenario))
            for name in sorted(recorders):
                if procs[name].poll() is None and stopped_for(procs[name], STOPPED_LIMIT):
                    LOG.error('recorder %s is stopped (SIGSTOP or a debugger) for %.0f s; '
                              'killing it', name, STOPPED_LIMIT)
                    procs[name].kill()
                    procs[name].wait()
            dead = {n for n, p in procs.items() if p.poll() not in (None, 0)} - reported
            for name in sorted(dead):
                if forwarded and procs[name].poll() == shutdown.exit_code():
                    LOG.info('node %s stopped on the forwarded %s', name,
                             shutdown.signal_name())       # its clean stop, not an error
                    continue
                _log_end(name, procs[name].poll())
                if procs[name].poll() == exits.PLANT_STALLED:
                    cause = cause or 'stalled'      # the plant is stuck: no grace helps it
                elif name in recorders and procs[name].poll() != exits.RECORDING_FAILED:
                    cause = cause or 'recording'    # the run's record is lost from here on
                # (a recorder's report failed (3) after the run ended: the plant's own end,
                # an error that stopped its run, comes next and is the cause)
                # a dead source stops a lockstep plant with a named error; give it the time
                end = min(end, time.monotonic() + (0.0 if cause else _plant_grace(scenario)))
            reported |= dead
            if time.monotonic() > end:
                if cause is None and reported and not forwarded:
                    LOG.error('stopping the plant: it did not end within %.0f s after %s '
                              'failed', _plant_grace(scenario), ', '.join(sorted(reported)))
                elif cause is None:
                    LOG.error('plant did not end in time (timeout %.0f s, or the grace after '
                              'a stop signal); stopping it', timeout)
                else:
                    LOG.error('stopping the plant: %s', 'it stalled' if cause == 'stalled'
                              else 'a recorder failed')
                break
            time.sleep(0.1)
        code = plant.poll()
        if code == 0 and not composed:       # a composition drains its recorder itself
            drain_recorders(scenario, procs)
        # nodes that failed by themselves; those stopped below exit with 130 (SIGINT)
        failed = {n: p.poll() for n, p in procs.items() if p.poll() not in (0, None)
                  and not (forwarded and p.poll() == shutdown.exit_code())}
    finally:
        # a recorder after SIGINT waits for the plant's end announcement, then drains; the
        # plant waits up to ack_timeout for its subscribers' acknowledgements
        graces = {n.name: n.params.drain_timeout + 5.0 for n in scenario.of_role(RECORDER)}
        graces[scenario.plant.name] = scenario.plant.params.ack_timeout + 5.0
        stopped = stop(procs, graces=graces)
        tmp.cleanup()
        for stream in logs:
            stream.close()
    if code is not None and stopped and not forwarded:   # the plant ended by itself
        LOG.info('stopped after the plant ended: %s', ', '.join(
            f'{name} ({describe_exit(rc)})' for name, rc in stopped.items()))
    for name, rc in failed.items():
        if name not in reported:
            _log_end(name, rc)
    return _end_code(scenario, code, failed, {**stopped, **failed}, cause)


def _log_end(name: str, rc: int | None) -> None:
    """Log how a node ended: a clean stop on a signal (128 + N) as a warning, else an error."""
    if rc is not None and rc in {exits.of_signal(s) for s in shutdown.STOP_SIGNALS}:
        LOG.warning('node %s stopped by %s (exit code %d)', name,
                    signal.Signals(rc - exits.SIGNAL_BASE).name, rc)
    else:
        LOG.error('node %s %s', name, describe_exit(rc))


def _end_code(scenario: Scenario, code: int | None, failed: dict[str, int | None],
              ends: dict[str, int | None], cause: str | None) -> int:
    """The runner's exit code (:mod:`pentapod_sim.exits`), the reason logged by name."""
    if shutdown.requested():
        return shutdown.exit_code()
    stalled = sorted(n for n, rc in failed.items() if rc == exits.PLANT_STALLED)
    if stalled:
        LOG.error('the plant %s stalled (seen by %s); it was stopped',
                  scenario.plant.name, ', '.join(stalled))
        return exits.PLANT_STALLED
    recorders = {n.name for n in scenario.of_role(RECORDER)}
    # SIGINT (130): the runner stopped it and it closed its bag (a failed report exits 3)
    bad = {n: rc for n, rc in ends.items() if n in recorders
           and rc not in (0, None, exits.of_signal(signal.SIGINT))}
    if bad and (code == 0 or cause == 'recording'):
        for name, rc in sorted(bad.items()):
            LOG.error('recording failed: recorder %s %s; %s', name, describe_exit(rc),
                      'its bag is closed, its report (above) says why it cannot be trusted'
                      if rc == exits.RECORDING_FAILED else 'its bag is incomplete'
                      + (' (no footer: `analyze recover`)' if rc is not None and rc < 0
                         else ''))
        return exits.RECORDING_FAILED
    if code is None:        # a node that failed first is the cause (named above)
        return exits.ERROR if failed else exits.TIMEOUT
    if code == 0 and failed:
        return exits.ERROR
    return exits.of_returncode(code)


def _forward(procs: dict[str, Proc], name: str) -> None:
    """Send the stop signal this process received to every running node."""
    LOG.warning('%s received: stopping the nodes', name)
    for proc in procs.values():
        if proc.poll() is None:
            proc.send_signal(signal.Signals[name])


def main(argv=None) -> int:
    """Entry point of ``ros2 run pentapod_testbed scenario <name or file>``."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     allow_abbrev=False)
    parser.add_argument('scenario', help='scenario name (config/scenarios) or YAML file')
    parser.add_argument('--steps', type=int, help='override plant steps')
    parser.add_argument('--duration', type=float, help='override plant duration [s]')
    parser.add_argument('--timing', choices=['lockstep', 'realtime'])
    parser.add_argument('--model-file', help='override plant model_file')
    parser.add_argument('--output-file', help='plant trace .npz (y_k, u_k per step)')
    parser.add_argument('--domain-id', type=int,
                        help='ROS_DOMAIN_ID for all nodes (default: $ROS_DOMAIN_ID, else a '
                        'free domain reserved for the run)')
    parser.add_argument('--timeout', type=float, default=3600.0,
                        help='wall-time limit of the run [s]')
    parser.add_argument('--list', action='store_true', help='only print the nodes')
    parser.add_argument('--composed', action='store_true',
                        help='run every node in one process on one executor')
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(message)s')
    shutdown.install()
    try:
        path = resolve(args.scenario)
        if args.list:
            for node in read_scenario(path).nodes:
                print(f'{node.name}: {node.executable} ({node.node_class})')
            return 0
        overrides = {key: value for key, value in (
            ('steps', args.steps), ('duration', args.duration), ('timing', args.timing),
            ('model_file', args.model_file), ('output_file', args.output_file))
            if value is not None}
        env = dict(os.environ)
        if args.domain_id is not None:
            env[DOMAIN_VAR] = str(args.domain_id)
        return run_scenario(path, overrides, args.timeout, env, composed=args.composed)
    except (ConfigError, RunError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    raise SystemExit(main())
