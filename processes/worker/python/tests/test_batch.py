"""Batch workers (``serve(batch_rollout=...)``): whole batches per call, failures counted per
task, and a run served to its end with the per-task worker's results."""

from __future__ import annotations

import unittest
from typing import Any

import numpy as np

import acps_worker
from acps_worker import Exit
from acps_worker.batch import TaskBatch

from .support import ROOT, Learner, leftovers, run_name
from .test_bowl import bowl_example

BOWL_TOML = ROOT / "experiments" / "bowl.toml"
WIDE = ["--config", str(BOWL_TOML), "--in-flight", "32", "--episodes", "320", "--runs", "1"]


def final_scores(summary: dict[str, Any]) -> dict[str, list[float]]:
    return {name: m["final_scores"] for name, m in summary["methods"].items()}


class BatchTest(unittest.TestCase):
    def serve_bowl(self, test: str, **kwargs: Any) -> tuple[acps_worker.Report, dict[str, Any]]:
        report, summary, _ = self.serve_bowl_logged(test, **kwargs)
        return report, summary

    def serve_bowl_logged(
        self, test: str, **kwargs: Any
    ) -> tuple[acps_worker.Report, dict[str, Any], str]:
        """A worker serving the wide bowl run to its end: its report, the summary and what the
        learner printed."""
        bowl = bowl_example()
        run = run_name(test)
        learner = Learner(run, WIDE)
        try:
            report = acps_worker.serve(run=run, environment=bowl.BOWL, **kwargs)
        finally:
            summary = learner.finished()
        self.assertEqual(leftovers(run), [])
        return report, summary, learner.output()

    def test_batches_hold_many_tasks_and_give_the_per_task_results(self) -> None:
        bowl = bowl_example()
        sizes: list[int] = []

        def batch_rollout(batch: TaskBatch) -> Any:
            sizes.append(len(batch))
            self.assertEqual(batch.contexts.shape, (len(batch), 2))
            self.assertEqual(batch.thetas.shape, (len(batch), 4))
            self.assertTrue(batch.thetas.flags.c_contiguous)
            self.assertTrue(set(batch.kinds) <= {"train", "evaluate", "baseline"})
            return bowl.batch_rollout(batch)

        report, batched = self.serve_bowl("batch", batch_rollout=batch_rollout, queue_depth=32)
        self.assertEqual((report.exit, report.failed), (Exit.FINISHED, 0))
        self.assertEqual(report.rollouts, sum(sizes))
        self.assertGreater(max(sizes), 8, f"batch sizes {sorted(set(sizes))}")
        _, per_task = self.serve_bowl("per-task", rollout=bowl.rollout)
        self.assertEqual(final_scores(batched), final_scores(per_task))

    def test_failed_tasks_and_failed_batches_are_counted_and_asked_again(self) -> None:
        bowl = bowl_example()
        calls = [0]

        def flaky(batch: TaskBatch) -> Any:
            calls[0] += 1
            if calls[0] == 1:
                raise RuntimeError("the simulator is not warm yet")
            if calls[0] == 2:
                return np.zeros(len(batch) + 1), np.zeros(len(batch))
            rewards, scores = bowl.batch_rollout(batch)
            ok = np.ones(len(batch), dtype=bool)
            if calls[0] == 3:
                ok[0] = False
                scores[-1] = np.nan
            return rewards, scores, ok

        with self.assertLogs("acps_worker", level="ERROR") as logs:
            report, summary, learner_log = self.serve_bowl_logged(
                "batch-fail", batch_rollout=flaky, queue_depth=32
            )
        # The learner says so at the worker's first outcome, with the sizes its tasks carry.
        self.assertIn("a worker's first rollout (task", learner_log)
        self.assertIn("the job's tasks carry contexts of 2 and parameters of 4 values", learner_log)
        self.assertEqual(report.exit, Exit.FINISHED)
        self.assertIn("the batch rollout of", logs.output[0])
        self.assertIn("RuntimeError: the simulator is not warm yet", logs.output[0])
        self.assertGreaterEqual(report.failed, 3)
        self.assertEqual(
            sum(m["failed_episodes"] for m in summary["methods"].values())
            + sum(m["failed_evaluation_rollouts"] for m in summary["methods"].values()),
            0,
            "a failed rollout is asked again once, and its second try succeeded",
        )

    def test_exactly_one_rollout_function(self) -> None:
        bowl = bowl_example()
        with self.assertRaises(TypeError):
            acps_worker.serve(run="unused")
        with self.assertRaises(TypeError):
            acps_worker.serve(bowl.rollout, "unused", batch_rollout=bowl.batch_rollout)


if __name__ == "__main__":
    unittest.main()
