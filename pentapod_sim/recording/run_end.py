"""
The end of a run as the plant announces it, and the recorder's check that every step is in.

The plant publishes its run status on :data:`pentapod_sim.interface.RUN_STATUS` (key/value
pairs :data:`pentapod_sim.interface.RUN_STATUS_KEYS`): ``running`` at the start, ``finished``
or ``stopped`` with the number of steps run at the end. Reliable delivery is in order per
publisher, so once a per-step topic holds the stamp of the last step, everything before it that
was not lost is in as well: the recorder stops once no topic is short of it
(:meth:`StepLedger.pending`), not after a wall time without messages. See docs/recording.md.
"""
from __future__ import annotations

from dataclasses import dataclass
import time
from typing import Any, Callable, Iterable, Mapping

import yaml

from pentapod_sim.errors import BagError
from pentapod_sim.interface import (
    is_step_topic,
    RUN_FINISHED,
    RUN_RUNNING,
    RUN_STATUS_KEYS,
    RUN_STOPPED,
)

#: MCAP metadata record (metadata.yaml ``custom_data`` key ``pentapod_start.initial_state``)
#: where the recorder notes where the plant started: ``rest`` or ``file <path>``, and (key
#: ``pentapod_start.drives``) the feed drives it stepped: ``none`` or ``<file> on struts [...]``.
START_RECORD = 'pentapod_start'

@dataclass(frozen=True)
class RunStatus:
    """
    One run-status message.

    Attributes
    ----------
    state : str
        ``running``, ``finished`` or ``stopped``.
    steps : int
        Steps run so far (stamps t_0 ... t_{steps-1} were published).
    dt : float
        Sample time [s].
    last_stamp_ns : int
        Stamp [ns] of the last step run; -1 if none.
    step_topics : tuple of str
        Topics the plant published or awaited every step.
    initial_state : str
        ``rest``, or ``file <path>``: the plant's state at step 0 came from that file.
    drives : str
        ``none``, or ``<file> on struts [...]``: the plant stepped the feed drives' rotors.
    """

    state: str
    steps: int
    dt: float
    last_stamp_ns: int
    step_topics: tuple[str, ...]
    initial_state: str = 'rest'
    drives: str = 'none'

    @property
    def ended(self) -> bool:
        """True for ``finished`` and ``stopped``."""
        return self.state in (RUN_FINISHED, RUN_STOPPED)

    @classmethod
    def from_values(cls, values: Mapping[str, str]) -> RunStatus:
        """Parse the key/value pairs of a status message (BagError names a bad value)."""
        missing = [k for k in RUN_STATUS_KEYS if k not in values]
        if missing:
            raise BagError(f'run status lacks key(s) {missing}: {dict(values)}')
        state = values['state']
        if state not in (RUN_RUNNING, RUN_FINISHED, RUN_STOPPED):
            raise BagError(f'run status has unknown state {state!r}')
        try:
            steps, dt = int(values['steps']), float(values['dt'])
            last = int(values['last_stamp_ns'])
        except ValueError as err:
            raise BagError(f'run status has a bad number: {err}') from None
        if steps < 0:
            raise BagError(f'run status has steps = {steps} < 0')
        topics = tuple(t for t in values['step_topics'].split(',') if t)
        return cls(state, steps, dt, last, topics, values.get('initial_state', 'rest'),
                   values.get('drives', 'none'))


def note_start(writer: Any, status: RunStatus) -> None:
    """Store where the plant started (:data:`START_RECORD`) in ``writer``'s bag, once."""
    record = {'initial_state': status.initial_state, 'drives': status.drives}
    if any(writer.custom_data.get(f'{START_RECORD}.{k}') != v for k, v in record.items()):
        writer.add_record(START_RECORD, record)


class StepLedger:
    """
    What a recorder wrote per stamped topic: unique steps, conflicting copies, the newest stamp.

    A stamp already written comes again when a lockstep plant re-sends a step (the same bytes:
    the recorder skips it) or when a second writer publishes the same step with other content:
    a *conflicting* copy, written (the bag keeps the evidence) and counted; the end report then
    fails (:func:`failures`). Unique stamps are kept per topic (a set: about 60 bytes a step).

    Parameters
    ----------
    selected : callable
        ``selected(topic)`` is True for topics the recorder records.
    """

    def __init__(self, selected: Callable[[str], bool]) -> None:
        self.selected = selected
        self.newest: dict[str, int] = {}
        self.stamps: dict[str, set[int]] = {}
        self.conflicting: dict[str, int] = {}
        self.noted = time.monotonic()         # wall time [s] of the last note

    def note(self, topic: str, stamp_ns: int) -> bool:
        """
        Note a message of ``topic`` with stamp ``stamp_ns`` that differs from the last one.

        Returns False (counted as conflicting) if the stamp was written before.
        """
        self.noted = time.monotonic()
        seen = self.stamps.setdefault(topic, set())
        if stamp_ns in seen:
            self.conflicting[topic] = self.conflicting.get(topic, 0) + 1
            return False
        seen.add(stamp_ns)
        if stamp_ns > self.newest.get(topic, -1):
            self.newest[topic] = stamp_ns
        return True

    def expected_topics(self, end: RunStatus, present: Iterable[str]) -> list[str]:
        """
        Topics that must hold one message per step.

        These are the plant's announced per-step topics and every other per-step topic
        (excitation, PMA state, forces) that has a publisher or a message (``present``), as
        far as the recorder selects them.
        """
        topics = [t for t in end.step_topics if self.selected(t)]
        topics += sorted(t for t in set(present) - set(topics)
                         if is_step_topic(t) and self.selected(t))
        return topics

    def pending(self, end: RunStatus, topics: Iterable[str]) -> list[str]:
        """The topics of ``topics`` that do not hold the stamp of the last step yet."""
        return [t for t in topics if self.newest.get(t, -1) < end.last_stamp_ns]

    def report(self, end: RunStatus, topics: Iterable[str],
               counts: Mapping[str, int]) -> dict[str, dict[str, int]]:
        """
        ``{topic: {'expected', 'recorded', 'unique', 'conflicting'}}`` per per-step topic.

        ``expected``: the steps of the run; ``recorded``: messages written; ``unique``: steps
        of the run (stamps up to the last one) among them; ``conflicting``: copies of a step
        already written, with other content.
        """
        last = end.last_stamp_ns
        return {t: {'expected': end.steps, 'recorded': int(counts.get(t, 0)),
                    'unique': sum(1 for s in self.stamps.get(t, ()) if s <= last),
                    'conflicting': self.conflicting.get(t, 0)}
                for t in topics}


def shortfalls(report: Mapping[str, Mapping[str, int]]) -> dict[str, int]:
    """Return ``{topic: missing steps}`` of the topics with fewer unique steps than expected."""
    return {t: c['expected'] - c.get('unique', c['recorded']) for t, c in report.items()
            if c.get('unique', c['recorded']) < c['expected']}


def failures(report: Mapping[str, Mapping[str, int]],
             foreign: Mapping[str, str]) -> list[str]:
    """
    Why a recording cannot be trusted, one text per reason (empty: complete and clean).

    Missing steps, conflicting copies of a step, and ``foreign``: topic -> the second writers
    a recorder saw (:mod:`pentapod_sim.nodes.writers`).
    """
    out = [f'{t} misses {n} of {report[t]["expected"]} steps'
           for t, n in shortfalls(report).items()]
    out += [f'{t} holds {c["conflicting"]} conflicting copies of steps (a second writer)'
            for t, c in report.items() if c.get('conflicting')]
    out += [f'{t}: {text}' for t, text in foreign.items()]
    return out


#: ``run_state`` of a report whose plant announced no end (killed, or never ran).
NO_END = 'no end announced'


def report_record(end: RunStatus | None, report: Mapping[str, Mapping[str, int]],
                  foreign: Mapping[str, str]) -> dict[str, object]:
    """
    The recorder's record of a run's end in its bag (MCAP metadata ``pentapod_recording``).

    ``run_state``, ``steps`` and per topic ``expected``, ``recorded`` (messages), ``unique``
    (steps), ``missing`` (steps), ``conflicting`` (copies), and ``foreign`` (topic -> the
    second writers seen); docs/recording.md. Without an end announcement (``end`` None):
    ``run_state`` :data:`NO_END`, ``steps`` -1, no counts, the foreign writers seen.
    """
    def flow(mapping: Mapping[str, object]) -> str:
        return yaml.safe_dump(dict(mapping), default_flow_style=True, sort_keys=False,
                              width=1 << 20).strip()

    def per_topic(key: str) -> str:
        return flow({t: c[key] for t, c in report.items()})
    return {'run_state': end.state if end else NO_END, 'steps': end.steps if end else -1,
            'expected': per_topic('expected'), 'recorded': per_topic('recorded'),
            'unique': per_topic('unique'), 'missing': flow(shortfalls(report)),
            'conflicting': flow({t: c['conflicting'] for t, c in report.items()
                                 if c['conflicting']}),
            'foreign': flow(foreign)}
