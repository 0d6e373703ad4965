"""Ablation studies: a declarative grid of cells (``study``) sharing one set of settings
(``settings``), the work of one cell (``cell``), where cells run (``executor``) and the
resumable runner (``runner``).

``pneubayes ablate STUDY.toml --out RUNDIR`` is the command line. Dask is imported only
by :class:`~pneubayes.ablation.executor.DaskExecutor`.
"""

from pneubayes.ablation.cell import run_cell
from pneubayes.ablation.executor import DaskExecutor, Executor, LocalExecutor
from pneubayes.ablation.runner import run_study
from pneubayes.ablation.settings import Settings
from pneubayes.ablation.study import Cell, Study, StudyError, load_study, parse_study

__all__ = ["Cell", "DaskExecutor", "Executor", "LocalExecutor", "Settings", "Study",
           "StudyError", "load_study", "parse_study", "run_cell", "run_study"]
