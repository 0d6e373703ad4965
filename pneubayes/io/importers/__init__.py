"""Importers of third-party recordings: each writes format-2 recordings and a rig card
(``pneubayes import NAME ...``); they never modify their input."""

from pneubayes.io.importers.gtdynamics import import_gtdynamics
from pneubayes.io.importers.respiraworks import import_respiraworks

IMPORTERS = {"gtdynamics": import_gtdynamics, "respiraworks": import_respiraworks}

__all__ = ["IMPORTERS", "import_gtdynamics", "import_respiraworks"]
