"""The "bowl" environment's worker in Python, the twin of processes/worker/examples/bowl.rs:
the same arithmetic in the same order, so that its outcomes are the Rust worker's bit for bit.

    acps run --config experiments/bowl.toml --worker-command "python examples/bowl.py"
"""

import math

import acps_worker

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


if __name__ == "__main__":
    acps_worker.serve(rollout, environment=BOWL)  # joins the run named by $ACPS_RUN
