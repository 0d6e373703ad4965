"""Discovery: where a fitted model disagrees with recordings, and which effect it misses.

Layers: :mod:`~pneubayes.simulation.rates` (the model's dp/dt at the measured state,
shared with the simulation layer), :mod:`~pneubayes.discovery.one_step` (dp/dt residuals
as one-step prediction errors),
:mod:`~pneubayes.discovery.library` (physically named candidate terms, each effect's
own: :mod:`~pneubayes.effects.discovery`),
:mod:`~pneubayes.discovery.candidates` (a named effect's forms beside the current fit),
:mod:`~pneubayes.discovery.sindy` (grouped sparse regression with block bagging),
:mod:`~pneubayes.discovery.openform` (the second resort: closure terms, extra mass flows
into the chamber, searched over a generic typed library),
:mod:`~pneubayes.discovery.disagreement` (residuals binned by operating regime),
:mod:`~pneubayes.discovery.verification` (held-out scores and the acceptance test),
:mod:`~pneubayes.discovery.rounds` (one round's candidate forms, cheapest first),
:mod:`~pneubayes.discovery.trials` (fitting and verifying trials, their basin controls),
:mod:`~pneubayes.discovery.state` (the data, the ledger and a round's state),
:mod:`~pneubayes.discovery.stages` (the pipeline after a round's trials: the other
supported groups, the last resort, the catalogue sweep, runner-ups, pairs, the named
effects' other forms),
:mod:`~pneubayes.discovery.settings` (every setting, saved with the result) and
:mod:`~pneubayes.discovery.loop` (fit, map, search, name, add, verify, repeat;
:func:`~pneubayes.discovery.loop.discover`), :mod:`~pneubayes.discovery.result` (what it
found, in memory) and :mod:`~pneubayes.discovery.report` (its run folder).
"""
