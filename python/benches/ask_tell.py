"""acps.Learner's cost per task from Python, at batch sizes 1, 32 and 1024.

    python python/benches/ask_tell.py [--episodes N] [--rounds R]

The learner is bowl.toml's problem (2-D contexts, 4 parameters, random contexts) with
``in_flight`` equal to the batch size, so that ``ask(batch)`` gets full batches. The time is that
of ``ask`` and ``tell`` only (the rollout is timed apart); rounds alternate the batch sizes, and
the median round is printed.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import tomllib

import acps

ROOT = Path(__file__).resolve().parents[2]


def settings(batch: int, episodes: int) -> dict[str, Any]:
    with open(ROOT / "experiments" / "bowl.toml", "rb") as f:
        values: dict[str, Any] = tomllib.load(f)
    values.update(methods=["random"], runs=1, episodes=episodes, in_flight=batch)
    return values


def one_round(batch: int, episodes: int) -> tuple[float, float, int]:
    """Seconds in ask/tell, seconds in the rollout, tasks."""
    learner = acps.Learner(settings(batch, episodes))
    learner_time = rollout_time = 0.0
    tasks_done = 0
    while not learner.done:
        start = time.perf_counter()
        tasks = learner.ask(batch)
        middle = time.perf_counter()
        d = tasks.thetas - np.tile(tasks.contexts, 2) * np.array([0.25, 0.5, 0.75, 1.0])
        total = (d * d).sum(axis=1)
        end = time.perf_counter()
        learner.tell(tasks.ids, -total, np.sqrt(total))
        learner_time += middle - start + time.perf_counter() - end
        rollout_time += end - middle
        tasks_done += len(tasks)
    return learner_time, rollout_time, tasks_done


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    batches = (1, 32, 1024)
    per_task: dict[int, list[float]] = {b: [] for b in batches}
    for r in range(args.rounds):
        for batch in batches:
            learner_time, _, tasks = one_round(batch, args.episodes)
            per_task[batch].append(learner_time / tasks * 1e6)
            print(
                f"round {r + 1}: batch {batch:5}: {per_task[batch][-1]:.2f} us per task", flush=True
            )
    for batch in batches:
        median = statistics.median(per_task[batch])
        print(f"batch {batch:5}: {median:.2f} us per task in ask/tell (median of {args.rounds})")


if __name__ == "__main__":
    main()
