"""
The "which damper to build" tables as CSV, Markdown and figures, and the issue's verdict.

Units: compliance um/N in the figures, ratios [-], forces N/N.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from pentapod_damper.design.rows import DRIVES_ROW
from pentapod_damper.design.table import DamperRow, DamperTable
from pentapod_sim.figures import save_figure
from pentapod_sim.sim.tuning import TuneSettings

#: The issue's target: TCP peak reduction of a strut-only law, and the static limit.
TARGET_REDUCTION, STATIC_LIMIT = 3.0, 1.1
COLUMNS = ('position', 'machine', 'law', 'sensors', 'actuators', 'gains', 'dynamics_included',
           'peak_reduction', 'rms_reduction', 'peak_hz', 'static_ratio', 'lowband_ratio',
           'check_margin', 'check_margin_extra_delay', 'effort_rms_n_per_n',
           'stroke_rms_per_n', 'stroke_unit',
           'struts12_share_peak', 'struts12_share_rms', 'feasible', 'strut_law', 'uses_drives',
           'note',
           'baseline_peak_um_per_n', 'baseline_peak_hz', 'direction', 'band_hz', 'sample_rate_hz',
           'delay_steps', 'check_modes', 'check_f_max_hz', 'tuning_grid',
           'full_check_margin', 'full_check_margin_extra_delay', 'full_check_modes',
           'full_check_f_max_hz')
Record = dict[str, str]


def _gains(row: DamperRow) -> str:
    return '; '.join(f'{k} {v:.6g}' for k, v in row.gains.items()) or '-'


def _grid(s: TuneSettings) -> str:
    """How the tuner searched: grid of the main gain x each other parameter, refinement."""
    return (f'{s.gain_points} gains x {s.grid_points} per other parameter, '
            f'{s.refine_iterations} Nelder-Mead iterations')


def records(table: DamperTable) -> list[Record]:
    """The table's rows as the text records of the CSV file (:data:`COLUMNS`)."""
    s = table.settings
    out = []
    for r in table.rows:
        values = [table.position, table.machine, r.law, r.sensors, r.actuators, _gains(r),
                  r.dynamics_included, r.peak_reduction, r.rms_reduction, r.peak_hz,
                  r.static_ratio, r.lowband_ratio, r.check_margin, r.check_margin_extra,
                  r.effort_rms_per_n, r.stroke_rms_per_n, r.stroke_unit or '',
                  r.share12_peak, r.share12_rms,
                  r.feasible and r.stable_on_check, r.strut_law, getattr(r, 'uses_drives', False),
                  r.note,
                  table.baseline_peak * 1e6,
                  table.baseline_peak_hz, s.direction, f'{s.band[0]:g}-{s.band[1]:g}',
                  s.sample_rate, s.dynamics.delay_steps, table.check_modes,
                  table.check_f_max_hz, _grid(s), r.full_check_margin,
                  r.full_check_margin_extra, table.full_check_modes, table.full_check_f_max_hz]
        out.append({k: str(v) for k, v in zip(COLUMNS, values)})
    return out


def write_csv(tables: Sequence[DamperTable], path: str | Path) -> Path:
    """One line per position, machine and law (:data:`COLUMNS`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, COLUMNS)
        writer.writeheader()
        for t in tables:
            writer.writerows(records(t))
    return path


def read_csv(path: str | Path) -> list[Record]:
    """The records of a file :func:`write_csv` wrote."""
    with open(path, newline='') as stream:
        return list(csv.DictReader(stream))


def _num(text: str, fmt: str = '.2f', scale: float = 1.0) -> str:
    value = float(text)
    return '-' if not math.isfinite(value) else format(value * scale, fmt)


def _blocks(rows: Sequence[Record]) -> dict[tuple[str, str, str], list[Record]]:
    """Records grouped by position, machine and the laws' delay, in file order."""
    blocks: dict[tuple[str, str, str], list[Record]] = {}
    for row in rows:
        blocks.setdefault((row['position'], row['machine'], row['delay_steps']), []).append(row)
    return blocks


def _recorded(position: str, law: str, recorded: Sequence[Record]) -> str:
    """The recorded runs' verdict of a row: modes within tolerance, largest ζ error."""
    mine = [r for r in recorded if (r['position'], r['law']) == (position, law)]
    if not mine:
        return '-'
    errors = [abs(float(r['zeta_error'])) for r in mine]
    worst = max(errors) if all(math.isfinite(e) for e in errors) else math.nan
    within = sum(r['within'] == 'True' for r in mine)
    return (f'{within}/{len(mine)} modes within, ζ error ' +
            (f'{worst:.1%}' if math.isfinite(worst) else 'unpaired'))


def markdown_records(rows: Sequence[Record], recorded: Sequence[Record] = ()) -> str:
    """
    Markdown tables of records (one per position and machine), with what they rest on.

    ``recorded``: the rows of the recorded runs' CSV
    (:func:`pentapod_damper.design.recorded.write_csv`), summarised per law.
    """
    text = []
    for (position, machine, delay), block in _blocks(rows).items():
        h = block[0]
        d = h['direction']
        text += [f'**{position}, machine {machine}, laws with {delay} sample(s) of delay** '
                 f'(TCP {d}{d} in {h["band_hz"]} Hz: '
                 f'baseline peak {_num(h["baseline_peak_um_per_n"], ".3g")} um/N at '
                 f'{_num(h["baseline_peak_hz"], ".1f")} Hz; laws sampled at '
                 f'{_num(h["sample_rate_hz"], "g")} Hz with {h["delay_steps"]} sample(s) of '
                 f'delay; check model: {h["check_modes"]} modes below '
                 f'{_num(h["check_f_max_hz"], "g")} Hz; tuning: '
                 f'{h.get("tuning_grid") or "not recorded"}). '
                 "**The laws' own dynamics are in the numbers** of every row but the ideal "
                 'one: their filters, the zero-order hold and the computational delay '
                 f'({delay} sample(s)), and the margins also with one sample more.', '',
                 '| law | sensors / actuators | gains | own dynamics in the numbers | peak / '
                 'RMS reduction | static (below f1/2) compliance | check margin, '
                 f'{delay} sample(s) of delay | check margin, {int(delay) + 1} sample(s) '
                 '(one extra) | force RMS [N/N] | stroke RMS per N | struts 1+2 share peak '
                 '/ RMS | meets limits | recorded run: identified ζ against the sampled '
                 'loop |',
                 '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
        for r in block:
            own = 'yes' if r['dynamics_included'] == 'True' else 'no (continuous, ideal)'
            text.append(
                f'| {r["law"]} | {r["sensors"]} / {r["actuators"]} | {r["gains"]} | {own} | '
                f'{_num(r["peak_reduction"])} / {_num(r["rms_reduction"])} | '
                f'x{_num(r["static_ratio"], ".3f")} (x{_num(r["lowband_ratio"])}) | '
                f'{_num(r["check_margin"], ".1e")} | {_num(r["check_margin_extra_delay"], ".1e")}'
                f' | {_num(r["effort_rms_n_per_n"], ".3g")} | {_stroke(r)} | '
                f'{_num(r["struts12_share_peak"], ".0f", 100)} / '
                f'{_num(r["struts12_share_rms"], ".0f", 100)} % | '
                f'{"yes" if r["feasible"] == "True" else "no"} | '
                f'{_recorded(position, r["law"], recorded)} |')
        text.append('')
    return '\n'.join(text).rstrip() + '\n'


def _stroke(r: Record) -> str:
    """Stroke RMS per N with its unit (um/N, urad/N), '-' where none."""
    unit = r.get('stroke_unit', '')
    if not unit or not math.isfinite(float(r.get('stroke_rms_per_n', 'nan'))):
        return '-'
    return f'{_num(r["stroke_rms_per_n"], ".3g", 1e6)} u{unit}'


def markdown(table: DamperTable) -> str:
    """One position's table in Markdown (:func:`markdown_records` of its records)."""
    return markdown_records(records(table))


def best_strut_law(rows: Sequence[Record], drives: bool = True,
                   low_band: bool = False) -> Record | None:
    """
    The strut-only law's record with the largest peak reduction that meets every limit.

    The feed drives alone (:data:`~pentapod_damper.design.rows.DRIVES_ROW`) are the machine
    with its position loops, not a law: never chosen.

    ``drives`` False leaves out the laws that need the feed drives' loops (their damping rests
    on the drives' estimated parameters). ``low_band`` also asks the compliance below half the
    first resonance to stay within the static limit (a position loop around a law can keep
    the static compliance and still soften the machine there; unknown counts as failed).
    """
    ok = [r for r in rows if r['strut_law'] == 'True' and r['feasible'] == 'True'
          and r['law'] != DRIVES_ROW                   # the machine's own loops, not a law
          and r['dynamics_included'] == 'True'
          and float(r['static_ratio']) <= STATIC_LIMIT * (1 + 1e-9)
          and (drives or r['uses_drives'] != 'True') and not _failed_full_check(r)
          and (not low_band or float(r['lowband_ratio']) <= STATIC_LIMIT * (1 + 1e-9))]
    return max(ok, key=lambda r: float(r['peak_reduction']), default=None)


def ideal_row(rows: Sequence[Record]) -> Record | None:
    """The paper's ideal damper's record (continuous, without the law's dynamics)."""
    return next((r for r in rows if r['strut_law'] == 'True'
                 and r['dynamics_included'] != 'True'), None)


def _over_drives(best: Record, drives: Record | None) -> str:
    """For a law in the drives' loops: what the drives alone give and what the law adds."""
    if drives is None or best['uses_drives'] != 'True' or best is drives:
        return ''
    alone = float(drives['peak_reduction'])
    return (f', of which the feed drives alone give {alone:.2f}x (the law adds '
            f'{float(best["peak_reduction"]) / alone:.2f}x on the machine with its drives)')


def _failed_full_check(r: Record) -> bool:
    """Checked on the full check model (:mod:`pentapod_damper.design.verify`) and unstable."""
    margins = [float(r.get(k, 'nan')) for k in ('full_check_margin',
                                                 'full_check_margin_extra_delay')]
    return any(math.isfinite(m) and m <= 0 for m in margins)


def _full_check(r: Record) -> str:
    """What the full check model says of a record ('' when it was not run)."""
    if not math.isfinite(float(r.get('full_check_margin', 'nan'))):
        return ''
    return (f'; on the full check model ({r["full_check_modes"]} modes below '
            f'{_num(r["full_check_f_max_hz"], "g")} Hz) margin '
            f'{_num(r["full_check_margin"], ".1e")} and '
            f'{_num(r["full_check_margin_extra_delay"], ".1e")} with one more sample')


def _sentence(best: Record, ideal: Record | None = None,
              drives: Record | None = None) -> str:
    reduction = float(best['peak_reduction'])
    hit = 'reaches' if reduction >= TARGET_REDUCTION else 'misses'
    keeps = ''
    if ideal is not None:
        keeps = (f' ({reduction / float(ideal["peak_reduction"]) * 100:.0f} % of the ideal '
                 f'bending damper\'s {_num(ideal["peak_reduction"])}x)')
    return (f'{best["law"]} ({best["gains"]}) {hit} the {TARGET_REDUCTION:g}x target with '
            f'{reduction:.2f}x{keeps}{_over_drives(best, drives)} '
            f'(RMS {_num(best["rms_reduction"])}x) at static compliance '
            f'x{_num(best["static_ratio"], ".3f")} (x{_num(best["lowband_ratio"])} below f1/2), '
            f'check-model margin {_num(best["check_margin"], ".1e")} and '
            f'{_num(best["check_margin_extra_delay"], ".1e")} with one more sample of delay'
            f'{_full_check(best)}; actuator force '
            f'{_num(best["effort_rms_n_per_n"], ".3g")} N RMS and stroke '
            f'{_stroke(best)} RMS per N of TCP force; '
            f'struts 1+2 alone give {_num(best["struts12_share_peak"], ".0f", 100)} % of its '
            f'peak and {_num(best["struts12_share_rms"], ".0f", 100)} % of its RMS improvement')


def verdict(rows: Sequence[Record]) -> str:
    """The issue's done-when, position by position, in sentences (from the records)."""
    out = []
    for (position, machine, delay), block in _blocks(rows).items():
        where = f'{position} (machine {machine}, laws with {delay} sample(s) of delay)'
        best, own = best_strut_law(block), best_strut_law(block, drives=False)
        if best is None:
            out.append(f'* {where}: no strut-only law meets the limits.')
            continue
        ideal = ideal_row(block)
        drives = next((r for r in block if r['law'] == DRIVES_ROW), None)
        text = f'* {where}: the best strut-only law, {_sentence(best, ideal, drives)}.'
        if own is not None and own is not best:
            text += f" Without the feed drives' loops: {_sentence(own, ideal)}."
        elif own is None:
            text += " No law without the feed drives' loops meets the limits."
        build = best_strut_law(block, low_band=True)
        if build is None:
            text += (' No strut-only law keeps the compliance below half the first resonance '
                     'within the static limit too.')
        else:
            text += (f' **To build: {build["law"]}**, the best strut-only law that also keeps '
                     f'the compliance below half the first resonance within '
                     f"x{STATIC_LIMIT:g} of the machine's"
                     + ('.' if build is best or build is own
                        else f': {_sentence(build, ideal)}.'))
        out.append(text)
    return '\n'.join(out)


def fill(text: str, name: str, block: str) -> str:
    """``text`` with the lines between ``<!-- name:begin -->`` and its end set to ``block``."""
    begin, end = f'<!-- {name}:begin -->\n', f'<!-- {name}:end -->'
    head, found, rest = text.partition(begin)
    if not found or end not in rest:
        raise ValueError(f'no {begin.strip()} ... {end} block')
    return head + begin + block.rstrip('\n') + '\n' + end + rest.split(end, 1)[1]


def plot(table: DamperTable, path: str | Path) -> Path:
    """|TCP FRF| of the baseline and every row, and the families' trade-off curves."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={'width_ratios': [3, 2]})
    freq = table.frequencies_hz
    for name, mag in table.magnitudes.items():
        style = {'color': 'k', 'lw': 1.6} if name == 'baseline' else {'lw': 0.9}
        ax.loglog(freq, np.asarray(mag) * 1e6, label=name, **style)
    s = table.settings
    ax.set_xlabel('frequency [Hz]')
    ax.set_ylabel(f'|TCP {s.direction}{s.direction} compliance| [um/N]')
    ax.set_title(f'{table.position}, machine {table.machine}: laws as tuned '
                 f'({s.sample_rate:g} Hz, {s.dynamics.delay_steps} sample delay)')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    for name, points in table.trade_offs.items():
        if points:
            ratio, reduction = zip(*points)
            bx.step(ratio, reduction, where='post', marker='o', ms=3, label=name)
    bx.axvline(STATIC_LIMIT, color='k', ls='--', lw=0.8)
    bx.axhline(TARGET_REDUCTION, color='grey', ls=':', lw=0.8)
    bx.set_xscale('log')
    bx.set_xlabel('static TCP compliance / machine without the law')
    bx.set_ylabel('TCP peak reduction [x]')
    bx.set_title('trade-off (robustly stable designs)')
    bx.grid(True, which='both', alpha=0.3)
    bx.legend(fontsize=7)
    return save_figure(fig, path)


def write_energy_csv(tables: Sequence[DamperTable], path: str | Path) -> Path:
    """Strain-energy shares of the modes that dominate the TCP, per position and group."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    seen = set()
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['position', 'mode', 'group', 'share'])
        for t in tables:
            if t.position in seen:
                continue
            seen.add(t.position)
            for mode, shares in t.energy.items():
                writer.writerows([t.position, mode, g, v] for g, v in shares.items())
    return path


def energy_lines(path: str | Path) -> str:
    """Markdown list of :func:`write_energy_csv`'s file (groups with at least 0.5 %)."""
    modes: dict[tuple[str, str], list[str]] = {}
    for row in read_csv(path):
        if float(row['share']) >= 0.005:
            modes.setdefault((row['position'], row['mode']), []).append(
                f'{row["group"]} {float(row["share"]) * 100:.0f} %')
    return '\n'.join(f'* {position} {mode}: {", ".join(parts)}'
                     for (position, mode), parts in modes.items()) + '\n'
