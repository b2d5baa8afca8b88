"""acps: active contextual policy search (Fabisch & Metzen, JMLR 2014) from Python.

One upper-level policy pi(theta | s) learns a whole family of tasks (C-REPS, or contextual
CMA-ES with ``learner = "c-cmaes"``) while a selector chooses which context to practise next.
:class:`Learner` is one run of an experiment or problem file as ask/tell over numpy arrays;
the ``acps`` command (installed with this package) runs whole experiments, fleets and plots.
"""

from acps._learner import KINDS, Evaluation, Learner, Settings, Tasks
from acps._native import AcpsError, CheckpointError, SettingsError, TellError, __version__

__all__ = [
    "KINDS",
    "AcpsError",
    "CheckpointError",
    "Evaluation",
    "Learner",
    "Settings",
    "SettingsError",
    "Tasks",
    "TellError",
    "__version__",
]
