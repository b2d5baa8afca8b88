"""acps: active contextual policy search (Fabisch & Metzen, JMLR 2014) from Python.

One upper-level policy pi(theta | s) learns a whole family of tasks (C-REPS, or contextual
CMA-ES with ``learner = "c-cmaes"``) while a selector chooses which context to practise next.
:class:`Learner` is one run of an experiment or problem file as ask/tell over numpy arrays;
:func:`run` runs a whole file in this process with your simulator and writes its run
directory; the ``acps`` command (installed with this package) runs experiments, fleets and
plots.
"""

from acps._learner import KINDS, Evaluation, Learner, Settings, Tasks
from acps._native import AcpsError, CheckpointError, SettingsError, TellError, __version__
from acps._run import BatchRollout, Progress, Rollout, TqdmBars, run

__all__ = [
    "KINDS",
    "AcpsError",
    "BatchRollout",
    "CheckpointError",
    "Evaluation",
    "Learner",
    "Progress",
    "Rollout",
    "Settings",
    "SettingsError",
    "Tasks",
    "TellError",
    "TqdmBars",
    "__version__",
    "run",
]
