"""The "bowl" environment's worker in Python, the twin of processes/worker/examples/bowl.rs:
the same arithmetic in the same order, so that its outcomes are the Rust worker's bit for bit.

    acps run --config experiments/bowl.toml --worker-command "python examples/bowl.py"

With ``--batch`` it serves whole batches with numpy (``batch_rollout``), the same bits again.
"""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING

import acps_worker

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from acps_worker.batch import TaskBatch

BOWL = acps_worker.Environment("bowl", settings="bowl v1", parameters=(0, 0, 0))


def rollout(task: acps_worker.Task) -> tuple[float, float] | None:
    """The squared distance of theta to the context's bowl bottom: reward -total, score sqrt."""
    d, n = len(task.context), len(task.theta)
    if d == 0:
        return None
    total = 0.0
    for i in range(n):
        e = task.theta[i] - task.context[i % d] * (i + 1) / n
        total += e * e
    return -total, math.sqrt(total)


def bowl(
    contexts: npt.NDArray[np.float64], thetas: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """:func:`rollout` of rows of contexts and parameters, column by column in the same order
    of operations."""
    import numpy as np

    n, d = thetas.shape[1], contexts.shape[1]
    total = np.zeros(len(thetas))
    for i in range(n):
        e = thetas[:, i] - contexts[:, i % d] * (i + 1) / n
        total = total + e * e
    return -total, np.sqrt(total)


def batch_rollout(
    batch: TaskBatch,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """:func:`rollout` of a whole batch."""
    return bowl(batch.contexts, batch.thetas)


if __name__ == "__main__":
    # Joins the run named by $ACPS_RUN.
    if "--batch" in sys.argv[1:]:
        acps_worker.serve(batch_rollout=batch_rollout, environment=BOWL, queue_depth=16)
    else:
        acps_worker.serve(rollout, environment=BOWL)
