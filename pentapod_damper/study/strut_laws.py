"""
The damper table's strut laws on the study's plant: TCP reductions and the struts 1+2 share.

docs/dampers.md's table ("Which damper to build", ``python -m pentapod_damper.design``) tunes
every strut law on its design plant, about an hour per position. This stage re-tunes nothing:
it takes each law as the design's scenario writer shipped it (``config/scenarios/<name>.yaml``
of :data:`pentapod_damper.design.scenarios.SCENARIOS`, the gains of the table's row at the
position the file names, P1) and closes it on the study's plant of every position, at the
scenario's own sample rate and computational delay, once on all five struts and once on
struts 1 and 2 only; at a position other than the file's, also with the gains of the table's
row there (the file's damper node with those gains, as the design's scenario writer makes it),
so the table's own rows are measured at every position (the shipped files, P1's absolute
gains, meet every limit of the tuner at P2 too: docs/dampers.md, "The shipped scenario files at
P2", :func:`pentapod_damper.design.verify.shipped_judge`). From the sampled loop's pole-residue
FRF (:class:`pentapod_sim.sim.loop_frf.SampledLoop`): the exact TCP peak (searched at the
resonances) and the band RMS of |H|, their reductions against the plant without laws sampled
alike, and the share of the all-strut improvement that struts 1+2 give
(:func:`~pentapod_damper.study.analytic.improvement_share`) by peak and by RMS.

The plant is the one the scenario's plant node steps
(:func:`pentapod_sim.scenario.laws.scenario_plant`): the study's plant of the position (the
modes config/reduction.yaml keeps, with the static correction), with the feed drives' rotors
for a scenario with ``drives``. Reductions are against the plant with locked drives (as the
design table's). Struts 1+2 only: the damper nodes' parameters cut to those struts (per-port
lists to their ports); a law inside the feed drives' loops keeps the drives of the other struts
holding their lengths (a second damper node with the drives alone), as the design table does:
the drives are the machine, the law is what is restricted. The loops are not checked on the
check model here (the design table's margins are); an unstable loop on the plant gives NaN.

Units: compliance um/N in the rows, frequencies Hz, ratios and shares [-].
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

from pentapod_damper.design.report import read_csv, Record
from pentapod_damper.design.scenarios import node_params, SCENARIOS, shipped_records
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_damper.study.analytic import improvement_share
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.records import PositionModel, Row, Table
from pentapod_sim.errors import ConfigError
from pentapod_sim.paths import share_dir
from pentapod_sim.scenario.files import executable_of, read_scenario
from pentapod_sim.scenario.laws import scenario_dt, scenario_plant
from pentapod_sim.sim.controllers import controller_of
from pentapod_sim.sim.design_models import load_design_model
from pentapod_sim.sim.law_families import StrutStiffness
from pentapod_sim.sim.loop_frf import SampledLoop

#: The struts of the partial loop (the paper's claim) and of the full one.
PARTIAL, ALL = (1, 2), (1, 2, 3, 4, 5)
#: Parameters of a damper node listing its struts, and their per-port lists (2 per strut).
STRUT_LISTS = {'iff_struts': (), 'lag_struts': ('lag_stiffness',),
               'bandpass_struts': (), 'ppf_struts': ('ppf_stiffness',), 'drive_struts': ()}
#: The damper node that keeps the other struts' drives holding their lengths.
REST_NODE = 'damper_rest_drives'


def design_table_path() -> Path:
    """
    The committed damper table, docs/results/dampers.csv (``python -m pentapod_damper.design``).

    In the package's share folder: a source checkout has it; an installed package has no
    docs/, and the stage then closes the laws as their scenario files ship them only.
    """
    return share_dir() / 'docs' / 'results' / 'dampers.csv'


@dataclass
class StrutLaws:
    """The table's strut laws at one position: one row per law (see the module docstring)."""

    position: str
    rows: list[Row]

    def describe(self) -> str:
        own = [r for r in self.rows if r['gains_tuned_at'] == self.position]
        laws = '; '.join(f'{r["law"]} {r["peak_reduction"]:.2f}x, struts 1+2 '
                         f'{percent(r["struts12_share_peak"])} / '
                         f'{percent(r["struts12_share_rms"])}' for r in own)
        return (f"{self.position}: the damper table's strut laws on the study's plant "
                f'({len(self.rows)} rows: all struts and struts 1+2), gains tuned here: {laws}')


def percent(value: float) -> str:
    """A share as a whole percentage ('-' for NaN: no improvement to share)."""
    return f'{value:.0%}' if math.isfinite(value) else '-'


def on_struts(sections: Mapping[str, Mapping[str, Any]],
              struts: Sequence[int]) -> dict[str, dict[str, Any]]:
    """
    A scenario's node sections with every damper law cut to ``struts``.

    Per-port lists (``lag_stiffness``, ``ppf_stiffness``: two values per strut, in the order
    of the node's strut list) keep the ports of those struts; a list of one value stays. The
    drives of the struts left out stay, without IFF (a node :data:`REST_NODE`).
    """
    out: dict[str, dict[str, Any]] = {}
    rest: list[int] = []
    for name, params in sections.items():
        section = dict(params)
        if executable_of(name) == 'damper':
            for key, per_port in STRUT_LISTS.items():
                listed = [int(i) for i in section.get(key, ()) if int(i) > 0]
                if not listed:
                    continue
                kept = [i for i in listed if i in struts]
                for value_key in per_port:
                    values = list(section.get(value_key, ()))
                    if len(values) == 2 * len(listed):
                        section[value_key] = [values[2 * listed.index(i) + k]
                                              for i in kept for k in (0, 1)]
                section[key] = kept or [0]
                if key == 'drive_struts':
                    rest += [i for i in listed if i not in struts]
        out[name] = section
    if rest:
        drives = next(p for p in sections.values() if p.get('drive_struts'))
        out[REST_NODE] = {k: v for k, v in drives.items()
                          if k in ('sample_rate', 'drive_file')}
        out[REST_NODE]['drive_struts'] = rest
    return out


def _metrics(plant: Any, sections: Mapping[str, Mapping[str, Any]], dt: float,
             pair: tuple[str, str], band: tuple[float, float]
             ) -> tuple[float, float, float, float]:
    """Exact peak [m/N], its frequency [Hz], band RMS [m/N], spectral radius (NaN: unstable)."""
    loop = SampledLoop(plant, [controller_of(law) for law in scenario_laws(sections, dt)], dt)
    if not loop.spectral_radius < 1.0:
        return math.nan, math.nan, math.nan, loop.spectral_radius
    frf = loop.output(*pair)
    peak = frf.peak(*band)
    return peak.value, peak.freq_hz, frf.rms(*band), loop.spectral_radius


def law_row(cfg: StudyConfig, model: PositionModel, law: str,
            record: Record | None = None,
            stiffness: StrutStiffness | None = None) -> Row:
    """
    One law of :data:`SCENARIOS` on the study's plant of ``model`` (module docstring).

    Without ``record``: the law as its scenario file ships it. With ``record`` (a row of the
    damper table, docs/results/dampers.csv) and the position's ``stiffness``: the scenario's
    damper node with the record's gains, sample rate and delay, as the design's scenario
    writer makes it (:func:`pentapod_damper.design.scenarios.node_params`).
    """
    scenario = SCENARIOS[law][0]
    parsed = read_scenario(scenario)
    sections = {name: dict(params) for name, params in parsed.sections.items()}
    dt, tuned_at = scenario_dt(parsed), str(parsed.plant.params.position)
    if record is not None:
        assert stiffness is not None
        dt, tuned_at = 1.0 / float(record['sample_rate_hz']), record['position']
        dampers = [n for n in sections if executable_of(n) == 'damper']
        if len(dampers) != 1:
            raise ConfigError(f'scenario {scenario}: {len(dampers)} damper nodes, not one')
        sections[dampers[0]] = {**node_params(record, stiffness),
                                'delay_steps': int(record['delay_steps'])}
    plant = scenario_plant(parsed, model.plant)
    pair = (f'tcp_displacement_{cfg.direction}', f'tcp_force_{cfg.direction}')
    band = (float(cfg.band[0]), float(cfg.f_max))
    base = SampledLoop(model.plant, [], dt).output(*pair)
    base_peak, base_rms = base.peak(*band), base.rms(*band)
    p_all, f_all, rms_all, radius = _metrics(plant, on_struts(sections, ALL), dt, pair, band)
    p_12, _, rms_12, radius_12 = _metrics(plant, on_struts(sections, PARTIAL), dt, pair, band)
    delays = {int(p.get('delay_steps', 0)) for name, p in sections.items()
              if executable_of(name) == 'damper'}
    return {
        'position': model.position, 'law': law, 'scenario': scenario,
        'gains_from': 'table' if record is not None else 'scenario',
        'gains_tuned_at': tuned_at,
        'sample_rate_hz': 1.0 / dt, 'delay_steps': max(delays, default=0),
        'plant_modes': model.plant.n_modes,
        'plant_f_max_hz': float(model.plant.omega.max()) / (2 * math.pi),
        'drives': plant is not model.plant,
        'baseline_peak_um_per_N': base_peak.value * 1e6, 'baseline_peak_hz': base_peak.freq_hz,
        'peak_um_per_N': p_all * 1e6, 'peak_hz': f_all,
        'peak_reduction': base_peak.value / p_all, 'rms_reduction': base_rms / rms_all,
        'peak_reduction_12': base_peak.value / p_12, 'rms_reduction_12': base_rms / rms_12,
        'struts12_share_peak': improvement_share(base_peak.value, p_12, p_all),
        'struts12_share_rms': improvement_share(base_rms, rms_12, rms_all),
        'spectral_radius': radius, 'spectral_radius_12': radius_12}


def design_records(path: Path | None = None) -> list[Record]:
    """The damper table's records (docs/results/dampers.csv of the checkout; none if absent)."""
    path = design_table_path() if path is None else path
    return read_csv(path) if path.is_file() else []


def position_laws(cfg: StudyConfig, model: PositionModel,
                  records: Sequence[Record] = ()) -> StrutLaws:
    """
    Every law of :data:`SCENARIOS` at one position: as shipped, and with the table's gains.

    A law whose scenario file was tuned at another position is also closed with the gains
    the table's row of this position holds (``records``: the damper table's, locked machine,
    the delay of the scenario files), so the table's own numbers are measured at every
    position.
    """
    rows, stiffness = [], None
    for law in SCENARIOS:
        rows.append(law_row(cfg, model, law))
        mine = [r for r in shipped_records(list(records), model.position)
                if r['law'] == law]
        if mine and rows[-1]['gains_tuned_at'] != model.position:
            if stiffness is None:
                stiffness = load_design_model(model.position, check=False,
                                              corners=False).stiffness
            rows.append(law_row(cfg, model, law, mine[0], stiffness))
    return StrutLaws(model.position, rows)


#: The stage's table in the study's output (strut_laws.csv) and in docs/results.
TABLE = 'strut_laws'


def strut_laws_table(cfg: StudyConfig, positions: Mapping[str, StrutLaws]) -> Table:
    """The rows of every position as the study's table :data:`TABLE`."""
    rows = [row for laws in positions.values() for row in laws.rows]
    text = ("The strut laws of the damper table (docs/dampers.md, \"Which damper to build\") as "
            'their scenario files ship them and, at the other positions, with the gains of the '
            "table's row there (gains_from: scenario or table; gains_tuned_at), closed "
            "on the study's plant of each position at the scenario's sample rate and delay, "
            'on all five struts and on struts 1 and 2 only (the drives of the other struts '
            "kept for a law inside the drives' loops). Exact peaks and band RMS "
            f'({cfg.band[0]:g}-{cfg.f_max:g} Hz) of TCP {cfg.direction}{cfg.direction} from the '
            "sampled loop's poles; reductions against the plant with locked drives; "
            'struts12_share_*: share of the all-strut improvement struts 1+2 give. No '
            "re-tuning, no check-model margin (the table's).")
    return Table(TABLE, "The damper table's strut laws on the study's plant", text, rows)
