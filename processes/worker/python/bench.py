"""Rollouts per second of Python workers through a real fleet.

A learner (``acps run function --workers 0``, the built-in contextual function with a random
context choice and ``--in-flight`` training tasks in flight) serves W Python worker processes,
each with a queue of ``--queue-depth`` tasks, whose rollout is trivial (``--rollout-us 0``) or
busy-waits that many microseconds. Each worker reports its rollouts, the seconds from joining
to the run's end and the CPU seconds it used; the rate is their total rollouts over the longest
of those times, and the workers' CPU per rollout says what one worker could deliver on a core of
its own (the learner's cost, 2-2.5 us per rollout of this problem, bounds the rate).

    python bench.py                                  # trivial rollouts, W = 1
    python bench.py --workers 1 2 --rollout-us 1000  # ~1 ms rollouts at W = 1 and W = 2
    python bench.py --batch                          # batch workers (numpy), trivial rollouts

``--acps`` (default ``$ACPS_BIN``, else the worktree's ``target/release/acps``) is the binary.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import acps_worker

if TYPE_CHECKING:
    from acps_worker.batch import TaskBatch

ROOT = Path(__file__).resolve().parents[3]


def worker(run: str, identity: str, rollout_us: int, queue_depth: int, batch: bool) -> None:
    """One worker process: serve ``run`` and print its report as JSON."""
    name, settings, parameters = json.loads(identity)
    environment = acps_worker.Environment(name, int(settings), tuple(parameters))
    spin = rollout_us * 1e-6
    clock = time.perf_counter

    def rollout(task: acps_worker.Task) -> tuple[float, float]:
        if spin:
            end = clock() + spin
            while clock() < end:
                pass
        return -abs(task.theta[0]), 1.0 + abs(task.theta[0])

    def batch_rollout(tasks: TaskBatch) -> tuple[Any, Any]:
        import numpy as np

        if spin:
            end = clock() + spin * len(tasks)
            while clock() < end:
                pass
        first = np.abs(tasks.thetas[:, 0])
        return -first, 1.0 + first

    cpu = time.process_time()
    if batch:
        report = acps_worker.serve(
            run=run, batch_rollout=batch_rollout, environment=environment, queue_depth=queue_depth
        )
    else:
        report = acps_worker.serve(rollout, run, environment=environment, queue_depth=queue_depth)
    print(
        json.dumps(
            {
                "exit": report.exit.value,
                "rollouts": report.rollouts,
                "seconds": report.seconds,
                "cpu": time.process_time() - cpu,
            }
        )
    )


def measure(
    acps: str,
    workers: int,
    episodes: int,
    rollout_us: int,
    queue_depth: int,
    batch: bool,
    in_flight: int,
) -> float:
    """Rollouts per second of ``workers`` Python workers; also prints the row."""
    run = f"bench-{os.getpid()}-{workers}"
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(
            [
                acps,
                "experiment",
                "function",
                "--runs",
                "1",
                "--episodes",
                "10",
                "--n-theta",
                "5",
                "--method",
                "random",
                "-q",
                "--out",
                out,
            ],
            check=True,
            capture_output=True,
        )
        env = acps_worker.Policy.load(out).environment
        assert env is not None
        identity = json.dumps([env.name, str(env.settings), list(env.parameters)])
    with tempfile.TemporaryDirectory() as out:
        learner = subprocess.Popen(
            [
                acps,
                "run",
                "function",
                "--runs",
                "1",
                "--episodes",
                str(episodes),
                "--n-theta",
                "5",
                "--method",
                "random",
                "--in-flight",
                str(in_flight),
                "--workers",
                "0",
                "--run",
                run,
                "-q",
                "--out",
                out,
            ],
            stdout=subprocess.DEVNULL,
        )
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    __file__,
                    "--worker",
                    run,
                    identity,
                    str(rollout_us),
                    str(queue_depth),
                    "batch" if batch else "one",
                ],
                stdout=subprocess.PIPE,
                text=True,
            )
            for _ in range(workers)
        ]
        outputs = [p.communicate(timeout=600)[0] for p in procs]
        if any(p.returncode != 0 for p in procs):
            # The learner would wait for workers for ever.
            learner.kill()
            learner.wait()
            raise SystemExit(f"a worker failed (exit codes {[p.returncode for p in procs]})")
        reports = [json.loads(out.strip().splitlines()[-1]) for out in outputs]
        rollouts = int(sum(r["rollouts"] for r in reports))
        seconds = float(max(r["seconds"] for r in reports))
        rate = rollouts / seconds
        cpu_us = 1e6 * sum(r["cpu"] for r in reports) / rollouts
        print(
            f"W={workers} {'batch ' if batch else ''}rollout={rollout_us} us "
            f"queue_depth={queue_depth} in_flight={in_flight}: {rollouts} rollouts in "
            f"{seconds:.3f} s = {rate:,.0f} rollouts/s; worker CPU {cpu_us:.2f} us per rollout "
            f"({1 / cpu_us:.2f} M/s per core)",
            flush=True,
        )
        try:
            # The measurement is done; the learner still writes its tables and plots.
            code = learner.wait(timeout=120)
        except subprocess.TimeoutExpired:
            learner.kill()
            learner.wait()
            print("  (the learner did not finish writing its outputs within 120 s: killed)")
        else:
            if code != 0:
                raise SystemExit(f"the learner failed with {code}")
    return rate


def main() -> None:
    """Parse the options and run the rows."""
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        batch = sys.argv[6] == "batch"
        worker(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), batch)
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--acps", default=os.environ.get("ACPS_BIN", str(ROOT / "target/release/acps"))
    )
    parser.add_argument("--workers", type=int, nargs="+", default=[1])
    parser.add_argument(
        "--episodes", type=int, help="default: 100000, or 2000 for --rollout-us >= 100"
    )
    parser.add_argument("--rollout-us", type=int, default=0)
    parser.add_argument(
        "--queue-depth",
        type=int,
        help="tasks each worker keeps asked for or queued (default: 128 with --batch, so that "
        "batches reach the wire's 64; else 64)",
    )
    parser.add_argument(
        "--in-flight",
        type=int,
        help="the learner's training tasks in flight (default: the queue depth)",
    )
    parser.add_argument(
        "--batch", action="store_true", help="batch workers: one numpy call per batch of tasks"
    )
    args = parser.parse_args()
    episodes = args.episodes or (2000 if args.rollout_us >= 100 else 100_000)
    queue_depth = args.queue_depth or (128 if args.batch else 64)
    in_flight = args.in_flight or queue_depth
    rates = [
        measure(
            args.acps,
            w,
            episodes,
            args.rollout_us,
            queue_depth,
            args.batch,
            in_flight,
        )
        for w in args.workers
    ]
    if len(rates) > 1:
        print(f"ratio W={args.workers[-1]} / W={args.workers[0]}: {rates[-1] / rates[0]:.2f}")
    assert all(math.isfinite(r) for r in rates)


if __name__ == "__main__":
    main()
