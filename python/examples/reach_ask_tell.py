"""A MuJoCo arm learns to reach any target from your own loop: acps.Learner's ask/tell over
whole batches of ``mujoco.rollout`` (the simulator of processes/worker/python/examples/
reach_batch.py, which its batch workers serve to ``acps run``: the same settings give the same
bits either way).

    python python/examples/reach_ask_tell.py [--episodes N] [--run R]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import tomllib

import acps

EXAMPLES = Path(__file__).resolve().parents[2] / "processes" / "worker" / "python" / "examples"
sys.path.insert(0, str(EXAMPLES))
from reach_batch import reach


def learn(episodes: int | None = None, run: int = 0) -> acps.Learner:
    """One run of reach_batch.toml (with ``episodes`` training episodes when given), learnt."""
    with open(EXAMPLES / "reach_batch.toml", "rb") as f:
        settings: dict[str, Any] = tomllib.load(f)
    if episodes is not None:
        settings["episodes"] = episodes
    learner = acps.Learner(settings, run=run)
    while not learner.done:
        # Everything the learner has ready: its window of training tasks, and evaluations.
        tasks = learner.ask(1024)
        rewards, scores = reach(tasks.contexts, tasks.thetas, tasks.seeds)
        learner.tell(tasks.ids, rewards, scores)
    return learner


def main() -> None:
    """Learn one run and print its test errors."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, help="training episodes (the file's: 1500)")
    parser.add_argument("--run", type=int, default=0, help="which run of the file (its seed)")
    args = parser.parse_args()
    started = time.perf_counter()
    learner = learn(args.episodes, args.run)
    seconds = time.perf_counter() - started
    first, last = learner.evaluations[0], learner.evaluations[-1]
    print(
        f"{learner.experiment}, {learner.method}, run {learner.run}: test error "
        f"{first.score:.2f} cm -> {last.score:.2f} cm after {last.episode} episodes "
        f"({seconds:.1f} s)"
    )


if __name__ == "__main__":
    main()
