"""The discovery loop's stages: what a round tries after its search's own trials.

Each stage is one object behind :class:`Stage` (one file each); a loop's pipeline is a
list of them, run in order (:class:`~pneubayes.discovery.loop.Discovery` ``stages``).
:func:`default_stages` is the pipeline the settings describe; ``stages=[]`` is the
plain name -> add -> refit -> verify loop. A stage of your own subclasses :class:`Stage`.
"""

from __future__ import annotations

from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.stages.catalogue_sweep import CatalogueSweep
from pneubayes.discovery.stages.command_clock_form import CommandClockForm
from pneubayes.discovery.stages.last_resort import LastResort
from pneubayes.discovery.stages.loaded_wall_form import LoadedWallForm
from pneubayes.discovery.stages.more_supported import MoreSupported
from pneubayes.discovery.stages.open_form import OpenForm
from pneubayes.discovery.stages.other_forms import OtherForms
from pneubayes.discovery.stages.pairs import Pairs
from pneubayes.discovery.stages.port_restriction_form import PortRestrictionForm
from pneubayes.discovery.stages.reading_command_form import ReadingCommandForm
from pneubayes.discovery.stages.reading_flow_form import ReadingFlowForm
from pneubayes.discovery.stages.reading_form import ReadingForm
from pneubayes.discovery.stages.reading_hinge_form import ReadingHingeForm
from pneubayes.discovery.stages.reading_play_form import ReadingPlayForm
from pneubayes.discovery.stages.runner_ups import RunnerUps
from pneubayes.discovery.stages.valve_dead_time_form import ValveDeadTimeForm
from pneubayes.discovery.stages.volume_form import VolumeForm
from pneubayes.discovery.stages.volume_play_form import VolumePlayForm


def default_stages(settings: DiscoverySettings) -> list[Stage]:
    """The pipeline ``settings.stages``
    (:class:`~pneubayes.discovery.settings.StageSettings`) describes, in the loop's order:
    the other supported groups, the last resort, the catalogue's sweep near the noise
    floor, the runner-ups, pairs and the named effects' other forms, then the open forms:
    the valve driver's clock, a dead time that depends on the supply, the reading's
    knees, relaxations, plays, lags of the command and terms of the port flows, a
    restriction at the port, the volume's hinges, its friction-held walls and a loaded
    wall, and the closure."""
    s = settings.stages
    stages: list[Stage] = []
    if s.more_supported:
        stages.append(MoreSupported())
    if s.last_resort:
        stages.append(LastResort(s.last_resort_min_gap_closed, s.last_resort_best_gap_closed))
    if s.catalogue_sweep_min_noise_ratio:
        stages.append(CatalogueSweep(s.catalogue_sweep_min_noise_ratio,
                                     s.catalogue_sweep_min_gap_closed,
                                     s.last_resort_best_gap_closed))
    if s.runner_ups:
        stages.append(RunnerUps(s.last_resort_min_gap_closed))
    if s.pair_members:
        stages.append(Pairs(s.pair_members, s.last_resort_min_gap_closed))
    if s.max_form_swaps:
        stages.append(OtherForms(s.max_form_swaps))
    # the open forms with a few physical parameters first (the reading's relaxations, the
    # volume's hinges), then the closure's library, which competes with them where they
    # close under half the gap: a generic closure that passes first would absorb what a
    # physical form expresses exactly (an accumulator's compliance, as pressure relaxations)
    if s.command_clock_min_noise_ratio:  # (a wait locked to a clock, before what it bends)
        stages.append(CommandClockForm(s.command_clock_min_noise_ratio))
    if s.valve_dead_time_min_noise_ratio:  # (the valve's timing, as the clock's)
        stages.append(ValveDeadTimeForm(s.valve_dead_time_min_noise_ratio))
    if s.reading_hinge_min_noise_ratio:  # (the reading's static map before its dynamics)
        stages.append(ReadingHingeForm(s.reading_hinge_min_noise_ratio))
    if s.reading_form_min_noise_ratio:
        stages.append(ReadingForm(s.reading_form_min_noise_ratio))
    if s.reading_play_min_noise_ratio:
        stages.append(ReadingPlayForm(s.reading_play_min_noise_ratio))
    if s.reading_command_min_noise_ratio:
        stages.append(ReadingCommandForm(s.reading_command_min_noise_ratio))
    if s.reading_flow_min_noise_ratio:
        stages.append(ReadingFlowForm(s.reading_flow_min_noise_ratio))
    if s.port_restriction_min_noise_ratio:  # (the ports' flows before the volume's)
        stages.append(PortRestrictionForm(s.port_restriction_min_noise_ratio))
    if s.volume_form_min_noise_ratio:
        stages.append(VolumeForm(s.volume_form_min_noise_ratio))
    if s.volume_play_min_noise_ratio:
        stages.append(VolumePlayForm(s.volume_play_min_noise_ratio))
    if s.loaded_wall_min_noise_ratio:
        stages.append(LoadedWallForm(s.loaded_wall_min_noise_ratio))
    if s.open_form_min_noise_ratio:
        stages.append(OpenForm(s.open_form_min_noise_ratio))
    return stages


__all__ = ["Stage", "CatalogueSweep", "CommandClockForm", "MoreSupported", "LastResort",
           "RunnerUps", "Pairs", "OtherForms", "OpenForm", "ReadingForm", "ReadingHingeForm",
           "ReadingPlayForm", "ReadingCommandForm", "ReadingFlowForm", "PortRestrictionForm",
           "VolumeForm", "VolumePlayForm", "LoadedWallForm", "ValveDeadTimeForm",
           "default_stages"]
