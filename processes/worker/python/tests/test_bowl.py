"""Python workers of a problem file (experiments/bowl.toml): refusals as both sides say them,
and the example worker serving the run to its end, leaving nothing in shared memory."""

from __future__ import annotations

import importlib.util
import unittest
from types import ModuleType

import acps_worker
from acps_worker import Environment, Exit, RefusedError, _wire

from .support import ROOT, Learner, leftovers, run_name

BOWL_TOML = ROOT / "experiments" / "bowl.toml"


def bowl_example() -> ModuleType:
    """examples/bowl.py as a module."""
    path = ROOT / "processes" / "worker" / "python" / "examples" / "bowl.py"
    spec = importlib.util.spec_from_file_location("bowl_example", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BowlTest(unittest.TestCase):
    """A learner of a problem file and Python workers."""

    def test_refusals_are_named_on_both_sides_and_the_example_finishes_the_run(self) -> None:
        """Another protocol version, other settings, no identity and other declared sizes are
        refused; the example's identity and sizes are admitted and serve the run to its end."""
        bowl = bowl_example()
        wanted = Environment("bowl", "bowl v1", (0, 0, 0))
        self.assertEqual(bowl.BOWL, wanted)
        run = run_name("bowl")
        learner = Learner(run, ["--config", str(BOWL_TOML), "--episodes", "60"])
        try:
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl.rollout, run, environment=bowl.BOWL, _protocol=6)
            self.assertEqual(
                refused.exception.reason,
                f"protocol version 6 here, {_wire.PROTOCOL_VERSION} at the learner (another build)",
            )
            other = Environment("bowl", "bowl v2")
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl.rollout, run, environment=other)
            # Both sides' settings texts, not only their hashes: the learner's comes from the
            # problem file (the learner's log names both too, checked below).
            both = (
                f'this worker serves {other} = "bowl v2"; the run\'s jobs need {wanted} = "bowl v1"'
            )
            self.assertEqual(refused.exception.reason, both)
            self.assertIn(
                f"refused this worker: {refused.exception.reason}", str(refused.exception)
            )
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl.rollout, run)
            self.assertEqual(
                refused.exception.reason,
                f'this worker serves no named environment; the run\'s jobs need {wanted} = "bowl v1"',
            )
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl.rollout, run, environment=bowl.BOWL, sizes=(2, 5))
            self.assertEqual(
                refused.exception.reason,
                "this worker serves contexts of 2 and parameters of 5 values; "
                "the run's jobs need contexts of 2 and parameters of 4 values",
            )
            with self.assertRaises(ValueError):
                acps_worker.serve(bowl.rollout, run, environment=bowl.BOWL, sizes=(0, 4))
            report = acps_worker.serve(bowl.rollout, run, environment=bowl.BOWL, sizes=(2, 4))
            self.assertEqual((report.exit, report.failed), (Exit.FINISHED, 0))
        finally:
            summary = learner.finished()
        self.assertEqual(summary["experiment"], "bowl")
        log = learner.output()
        self.assertIn(f"protocol 6 (ours {_wire.PROTOCOL_VERSION})", log)
        self.assertIn(
            f'it serves environment {other} = "bowl v2"; the jobs need {wanted} = "bowl v1"', log
        )
        self.assertIn(
            f'it serves environment no named environment; the jobs need {wanted} = "bowl v1"', log
        )
        self.assertIn(
            "it serves contexts of 2 and parameters of 5 values; "
            "the jobs need contexts of 2 and parameters of 4 values",
            log,
        )
        self.assertEqual(leftovers(run), [])


if __name__ == "__main__":
    unittest.main()
