"""Open-form discovery: a residual no catalogue effect names, searched over generic,
physically typed closure terms (extra mass flows into the chamber,
:mod:`pneubayes.effects.closure_features`).

:mod:`~pneubayes.discovery.openform.signals` (the features' signals along a recording
and the missing mass flow), :mod:`~pneubayes.discovery.openform.features` (the
candidate library) and :mod:`~pneubayes.discovery.openform.search`
(:class:`OpenFormSearch`).
"""

from pneubayes.discovery.openform.features import Candidate, candidate_terms
from pneubayes.discovery.openform.search import FoundTerm, OpenFormSearch, closure_spec
from pneubayes.discovery.openform.signals import missing_mass_flow, path_signals

__all__ = ["Candidate", "FoundTerm", "OpenFormSearch", "candidate_terms", "closure_spec",
           "missing_mass_flow", "path_signals"]
