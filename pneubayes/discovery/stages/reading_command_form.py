"""Stage: an open-form term at the reading that follows the valve's drive, when neither
the catalogue, the closure's mass flow nor a relaxation or play of the reading closes
the gap.

A sensor that shares the solenoid driver's ground, or feels its field or heat, reads
something of the command as well as the pressure: a shift that follows the command's
magnitude with the lag of what carries it, whatever the pressure does. This stage
searches the training windows' residual for lags of ``|u|``
(:class:`~pneubayes.discovery.openform.reading_command.CommandLagSearch`) and adds the
kept ones as one :class:`~pneubayes.effects.reading_command.ReadingCommand`, fitted,
pruned and weighed as :class:`~pneubayes.discovery.stages.component_form.ComponentForm`
does.
"""

from __future__ import annotations

from pneubayes.discovery.openform.reading import ReadingWindows, reading_windows
from pneubayes.discovery.openform.reading_command import CommandLagSearch
from pneubayes.discovery.stages.component_form import ComponentForm
from pneubayes.discovery.state import RoundState
from pneubayes.effects.reading_command import (
    ReadingCommand,
    command_gain_name,
    command_time_constant_name,
)

#: The component's name in a model and in the ledger.
COMMAND = "reading_command"


class ReadingCommandForm(ComponentForm):
    """Search the training windows' residual for lags of the command's magnitude in the
    reading and add them as a reading command lag (when it runs: :class:`ComponentForm`).

    Parameters
    ----------
    min_noise_ratio, compete_below_gap_closed : float
        As :class:`ComponentForm`'s.
    search : CommandLagSearch or None
        The residual search (its settings); None: ``CommandLagSearch()``.
    """

    name = "reading_command_form"
    component = COMMAND
    label = "reading command form"
    term_word = "lag of the command in the reading"
    search_class = CommandLagSearch

    def _search_data(self, state: RoundState, runner) -> list[ReadingWindows]:
        """The training windows as the current model predicts them, with each
        recording's command (:func:`~pneubayes.discovery.openform.reading.reading_windows`)."""
        return reading_windows(runner.data.train_ws, state.current.model,
                               state.current.params, runner.settings.fit.refine_solver)

    def _component(self, terms: int):
        return ReadingCommand(terms=terms)

    def _term_names(self, k: int) -> tuple[str, ...]:
        return command_gain_name(k), command_time_constant_name(k)

    def _searched_values(self, terms, params) -> dict[str, float]:
        out = {}
        for k, t in enumerate(terms):
            out[command_gain_name(k)] = t.gain
            out[command_time_constant_name(k)] = t.time_constant_s
        return out
