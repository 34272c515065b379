"""
The paper's struts 1+2 claim with the damper table's laws: the README's sentences.

The damper table (``python -m pentapod_damper.design``, docs/results/dampers.csv) names, per
position, the best strut-only law and the law to build (its verdict,
:func:`pentapod_damper.design.report.best_strut_law`); the study's stage *the damper table's
strut laws* (:mod:`pentapod_damper.study.strut_laws`, strut_laws.csv) closes those laws on the
study's plant, on all struts and on struts 1+2. :func:`claim_sentences` makes the README's
sentences from those two CSV files: the shares by peak and RMS, where the paper's "at least
70 %" holds for each law, and what the numbers rest on per position.
"""
from __future__ import annotations

from pathlib import Path

from pentapod_damper.design.report import best_strut_law
from pentapod_damper.study.report import read_csv
from pentapod_damper.study.strut_laws import percent
from pentapod_damper.study.strut_laws import TABLE as STRUT_LAWS

#: the paper's claim: struts 1 and 2 give at least this share of the all-strut improvement
PAPER_SHARE = 0.7
#: The damper table in docs/results, whose verdict names the laws the sentences speak of.
DESIGN_TABLE = 'dampers.csv'


def where(holding: list[str], positions: list[str]) -> str:
    """Where a claim holds, in words: ``holding`` of ``positions``."""
    if not holding:
        return 'at neither position' if len(positions) == 2 else 'at no position'
    if len(holding) == len(positions):
        return 'at both positions' if len(positions) == 2 else 'at every position'
    return 'at ' + ' and '.join(holding) + ' only'


def _design_block(records: list[dict[str, str]], position: str) -> list[dict[str, str]]:
    """The damper table's rows of a position: locked machine, the largest delay (as shipped)."""
    mine = [r for r in records if (r['position'], r['machine']) == (position, 'locked')]
    delay = max((int(r['delay_steps']) for r in mine), default=0)
    return [r for r in mine if int(r['delay_steps']) == delay]


def _own_row(rows: list[dict[str, str]], position: str, law: str) -> dict[str, str] | None:
    """The strut-law row of ``law`` at ``position`` with the gains tuned there."""
    return next((r for r in rows if (r['position'], r['law'], r['gains_tuned_at'])
                 == (position, law, position)), None)


def verdict_laws(results: Path, positions: list[str]
                 ) -> dict[str, dict[str, dict[str, str]]] | None:
    """
    The laws the damper table's verdict names, per role and position, with the stage's rows.

    Roles: ``best`` (the best strut-only law) and ``build`` (the law to build), chosen from
    ``dampers.csv`` as docs/dampers.md's verdict chooses them
    (:func:`pentapod_damper.design.report.best_strut_law`); value: the row of
    ``strut_laws.csv`` of that law with the gains tuned at the position. None if either file
    is missing or a law has no row.
    """
    if not ((results / DESIGN_TABLE).is_file() and (results / f'{STRUT_LAWS}.csv').is_file()):
        return None
    records, rows = read_csv(results / DESIGN_TABLE), read_csv(results / f'{STRUT_LAWS}.csv')
    out: dict[str, dict[str, dict[str, str]]] = {'best': {}, 'build': {}}
    for pos in positions:
        block = _design_block(records, pos)
        for role, chosen in (('best', best_strut_law(block)),
                             ('build', best_strut_law(block, low_band=True))):
            row = _own_row(rows, pos, chosen['law']) if chosen is not None else None
            if row is None:
                return None
            out[role][pos] = row
    return out


def _shares(rows: dict[str, dict[str, str]], positions: list[str]) -> str:
    return ' and '.join(f'{percent(float(rows[p]["struts12_share_peak"]))} / '
                        f'{percent(float(rows[p]["struts12_share_rms"]))} ({p})'
                        for p in positions)


def _law_names(rows: dict[str, dict[str, str]]) -> str:
    names = list(dict.fromkeys(r['law'] for r in rows.values()))
    return names[0] if len(names) == 1 else ', '.join(
        f'{r["law"]} at {p}' for p, r in rows.items())


def _named(rows: dict[str, dict[str, str]]) -> str:
    """The law's name; for a law in the drives' loops, what its struts 1+2 loop keeps."""
    drives = any(r['drives'] == 'True' for r in rows.values())
    return _law_names(rows) + (" (the feed drives' loops of all five struts in both loops, "
                               'only the law inside them cut to struts 1 and 2)' if drives
                               else '')


def _holds(rows: dict[str, dict[str, str]], positions: list[str]) -> str:
    """Where the paper's claim holds for one law, by peak and by RMS."""
    return ', '.join(
        f'by {name} ' + where([p for p in positions
                                if float(rows[p][f'struts12_share_{m}']) >= PAPER_SHARE],
                               positions)
        for m, name in (('peak', 'peak'), ('rms', 'RMS')))


def claim_sentences(results: Path, positions: list[str]) -> list[str]:
    """
    The README's sentences on the paper's struts 1+2 claim with the damper table's laws.

    From ``strut_laws.csv`` (the study's stage) for the laws ``dampers.csv``'s verdict names
    (:func:`verdict_laws`), and what they rest on per position. None without those files.
    """
    laws = verdict_laws(results, positions)
    if laws is None:
        return []
    best, build = laws['best'], laws['build']
    text = [
        'With the strut laws of the damper table ([docs/dampers.md](docs/dampers.md), its '
        "gains tuned at each position) closed on the study's plant, struts 1 and 2 alone give "
        f'{_shares(best, positions)} of the all-strut improvement by peak / RMS with the best '
        f'strut-only law, {_named(best)}, and {_shares(build, positions)} with the law to '
        f'build, {_named(build)}: the paper\'s "at least {PAPER_SHARE:.0%}" holds for the '
        f'first {_holds(best, positions)}, for the law to build {_holds(build, positions)}.']
    rows = {pos: [best[pos], build[pos]] for pos in positions}
    drives = list(dict.fromkeys(r['law'] for pos in positions for r in rows[pos]
                                if r['drives'] == 'True'))
    plants = ', '.join(f'{pos}: {rows[pos][0]["plant_modes"]} modes up to '
                       f'{float(rows[pos][0]["plant_f_max_hz"]):.0f} Hz' for pos in positions)
    sampling = {pos: f'{float(r["sample_rate_hz"]):g} Hz with {r["delay_steps"]} sample(s) of '
                     'computational delay' for pos in positions for r in rows[pos]}
    rates = (f'{next(iter(sampling.values()))} at every position'
             if len(set(sampling.values())) == 1
             else ', '.join(f'{v} at {p}' for p, v in sampling.items()))
    text.append(
        f"These shares rest on the study's plant of each position ({plants}: those "
        'config/reduction.yaml keeps, with the static correction of the others'
        + (f" and, for {', '.join(drives)}, the feed drives' rotors" if drives else '')
        + "; the table's own plant adds the struts' axial modes on their links), the laws "
        f'sampled at {rates} with their own filters, and reductions against the machine with '
        "locked drives; the stability margins are the table's.")
    return text
