"""
What one sweep computes per pose, and the digest that keys its results.

The machine, the reduction configuration and the scenarios' sections are read once on the
client and shipped with every task, so the workers of a remote cluster compute with the
client's configuration; the digest covers all of it, so a changed setting never reuses a
stored result.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import hashlib
import json
from pathlib import Path
from typing import Any, Sequence

from pentapod_damper.study.config import load_study_config
from pentapod_sim import __version__
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.machine_data import load_machine, machine_path
from pentapod_sim.plant.config import load_reduction_config
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.scenario.laws import scenario_drives

#: The open loop: the scenario without added damping (its rows carry the suffix ``open``).
OPEN_LOOP = 'baseline'
#: Scenarios whose ratio is the struts-1+2 share: (partial, full).
SHARE_PAIR = ('strut_damping_12', 'strut_damping_all')
#: Modes below this frequency [Hz] are searched for the first frame and first strut mode.
DEFAULT_MODE_F_MAX = 200.0


@dataclass(frozen=True)
class SweepSettings:
    """
    Settings of one sweep (SI units).

    Attributes
    ----------
    scenarios : tuple of str
        Damped scenarios of config/scenarios (the open loop is always computed).
    gain_factors : tuple of float
        Factors on every damper gain of each scenario (1 = the file's gains); a PMA's gain
        g is scaled, its proof mass kept.
    freq : tuple
        (f_min [Hz], f_max [Hz], n_points) of the analytic FRFs.
    band : tuple of float
        Band [Hz] of the peak and RMS of |H|.
    sample_rate : float
        Plant sample rate [Hz] of the sampled-loop stability column (zero-order hold, u_k
        answers y_k).
    pma_force_amplitude : float
        Harmonic TCP force [N] of the PMA stroke and force columns.
    mode_f_max : float
        Modes below this [Hz] are searched for the first frame and strut mode.
    machine, reduction : object
        :class:`MachineParams` and :class:`ReductionConfig` as loaded.
    sections : dict
        Scenario name -> its ``read_scenario(name).sections``.
    drives : dict
        Scenario name -> the feed drives its plant steps
        (:func:`pentapod_sim.scenario.laws.scenario_drives`; None: the locked machine).
    digest : str
        SHA-256 (hex) over everything above and the package version.
    """

    scenarios: tuple[str, ...]
    gain_factors: tuple[float, ...]
    freq: tuple[float, float, int]
    band: tuple[float, float]
    sample_rate: float
    pma_force_amplitude: float
    mode_f_max: float
    machine: Any
    reduction: Any
    sections: dict[str, dict[str, dict[str, Any]]]
    drives: dict[str, Any] = field(default_factory=dict)
    digest: str = ''

    def labels(self) -> list[tuple[str, str, float]]:
        """(column label, scenario, gain factor) of every damped loop."""
        out = []
        for name in self.scenarios:
            for factor in self.gain_factors:
                label = name if factor == 1.0 else f'{name}_x{factor:g}'
                out.append((label, name, float(factor)))
        return out

    def share_labels(self) -> list[tuple[str, str, str]]:
        """(suffix, label of struts 1+2, label of all struts) per gain factor, if both run."""
        if not all(s in self.scenarios for s in SHARE_PAIR):
            return []
        out = []
        for factor in self.gain_factors:
            tail = '' if factor == 1.0 else f'_x{factor:g}'
            out.append((tail, SHARE_PAIR[0] + tail, SHARE_PAIR[1] + tail))
        return out


def _file_bytes(path: Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError:
        return b''


def make_settings(scenarios: Sequence[str] | None = None,
                  gain_factors: Sequence[float] = (1.0,), study_config: str | None = None,
                  machine_file: str | None = None, reduction_file: str | None = None,
                  mode_f_max: float = DEFAULT_MODE_F_MAX,
                  n_points: int | None = None) -> SweepSettings:
    """
    Sweep settings from the study configuration (FRF grid, band, sample rate, PMA force).

    Parameters
    ----------
    scenarios : sequence of str, optional
        Default: the study's scenarios; ``baseline`` (the open loop) is dropped from the list.
    gain_factors : sequence of float
        Factors (> 0) on the scenarios' gains.
    study_config, machine_file, reduction_file : str, optional
        Other files than config/study.yaml, machine.yaml, reduction.yaml.
    mode_f_max : float
        Upper frequency [Hz] of the frame/strut mode search.
    n_points : int, optional
        Points of the FRF grid instead of the study's.

    Raises
    ------
    ConfigError
        Naming the bad file, scenario or value.
    """
    study = load_study_config(study_config)
    names = tuple(s for s in (scenarios or study.scenarios) if s != OPEN_LOOP)
    factors = tuple(float(f) for f in gain_factors)
    if not factors or any(not f > 0 for f in factors):
        raise ConfigError(f'gain factors must be > 0, got {list(gain_factors)}')
    if not mode_f_max > 0:
        raise ConfigError(f'mode_f_max must be > 0 Hz, got {mode_f_max!r}')
    sections, drives, texts = {}, {}, []
    for name in names:
        scenario = read_scenario(name)
        sections[name] = scenario.sections
        drives[name] = found = scenario_drives(scenario)
        texts.append(_file_bytes(scenario.path))
        if found is not None:          # the drives file's values count too
            texts.append(_file_bytes(Path(found.params.source)))
    machine = load_machine(machine_file)
    reduction = load_reduction_config(reduction_file)
    freq = (float(study.freq_grid[0]), float(study.freq_grid[1]),
            int(n_points or study.freq_grid[2]))
    if freq[2] < 2:
        raise ConfigError(f'the FRF grid needs >= 2 points, got {freq[2]}')
    settings = SweepSettings(names, factors, freq, (float(study.band[0]), float(study.f_max)),
                             float(study.sample_rate), float(study.pma_force_amplitude),
                             float(mode_f_max), machine, reduction, sections, drives)
    digest = hashlib.sha256(json.dumps({
        'version': __version__, 'scenarios': names, 'factors': factors, 'freq': freq,
        'band': settings.band, 'sample_rate': settings.sample_rate,
        'pma_force': settings.pma_force_amplitude, 'mode_f_max': settings.mode_f_max,
        'sections': sections}, sort_keys=True, default=str).encode())
    for data in [_file_bytes(machine_path(machine_file)),
                 _file_bytes(Path(reduction.source))] + texts:
        digest.update(hashlib.sha256(data).digest())
    return replace(settings, digest=digest.hexdigest())
