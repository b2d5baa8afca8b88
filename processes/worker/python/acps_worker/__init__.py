"""Python workers for acps fleets: serve the rollout tasks of an acps learner (C-REPS with
active context selection) over iceoryx2 shared memory, as the Rust workers do.

Example::

    import acps_worker

    def rollout(task):  # task.context, task.theta: sequences of float; task.seed: int;
        ...             # task.kind: "train", "evaluate" or "baseline"
        return reward, score  # floats; None (or raise) for a failed rollout

    acps_worker.serve(run="NAME", rollout=rollout)  # run defaults to $ACPS_RUN

A worker declares the environment it serves with ``environment=acps_worker.Environment(name,
settings="text", parameters=(0, 0, 0))``, which must equal the problem's; without one it serves
the unnamed environment of problems that name none. :func:`serve` returns a :class:`Report`
(why it stopped, rollouts, failed rollouts) and releases every shared-memory resource however
it ends. :class:`Policy` reads a learned policy of a run directory and computes its mean.
"""

from ._wire import PROTOCOL_VERSION
from .environment import Environment, fnv1a
from .errors import AcpsWorkerError, NoLearnerError, ProtocolError, RefusedError
from .policy import Policy
from .worker import Exit, Report, Task, serve

__all__ = [
    "PROTOCOL_VERSION",
    "AcpsWorkerError",
    "Environment",
    "Exit",
    "NoLearnerError",
    "Policy",
    "ProtocolError",
    "RefusedError",
    "Report",
    "Task",
    "fnv1a",
    "serve",
]
