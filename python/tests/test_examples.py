"""The vectorised MuJoCo arm (processes/worker/python/examples/reach_batch.py), learnt three
ways for a short run: `acps run` with batch workers, with per-task workers, and ask/tell from
python/examples/reach_ask_tell.py. All three give the same scores, bit for bit."""

from __future__ import annotations

import csv
import importlib.util
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]
WORKER = ROOT / "processes" / "worker" / "python" / "examples" / "reach_batch.py"
PROBLEM = WORKER.with_suffix(".toml")
EPISODES = 200


def ask_tell_example() -> ModuleType:
    path = ROOT / "python" / "examples" / "reach_ask_tell.py"
    spec = importlib.util.spec_from_file_location("reach_ask_tell", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def command_line_scores(worker: str) -> list[tuple[int, float]]:
    """Run 0's test errors from `acps run` of the problem with 2 workers `worker`."""
    acps = Path(sys.executable).parent / "acps"
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(
            [
                str(acps),
                "run",
                "--config",
                str(PROBLEM),
                "--episodes",
                str(EPISODES),
                "--runs",
                "1",
                "--workers",
                "2",
                "--worker-command",
                worker,
                "--out",
                out,
                "-q",
            ],
            check=True,
            timeout=600,
        )
        with open(Path(out) / "runs.csv", newline="") as f:
            return [(int(r["episode"]), float(r["score"])) for r in csv.DictReader(f)]


class ExamplesTest(unittest.TestCase):
    def test_batch_workers_per_task_workers_and_ask_tell_agree(self) -> None:
        batch = command_line_scores(f"{sys.executable} {WORKER} --batch")
        per_task = command_line_scores(f"{sys.executable} {WORKER}")
        self.assertEqual(batch, per_task)
        learner = ask_tell_example().learn(EPISODES)
        self.assertEqual([(e.episode, e.score) for e in learner.evaluations], batch)
        self.assertEqual(len(batch), EPISODES // 50 + 1)
        self.assertLess(batch[-1][1], batch[0][1] / 2, "the arm learns to reach")

    def test_the_ask_tell_script_runs(self) -> None:
        script = ROOT / "python" / "examples" / "reach_ask_tell.py"
        done = subprocess.run(
            [sys.executable, str(script), "--episodes", "100"],
            check=True,
            capture_output=True,
            text=True,
            timeout=600,
        )
        self.assertRegex(done.stdout, r"test error 55\.\d\d cm -> \d+\.\d\d cm after 100 episodes")


if __name__ == "__main__":
    unittest.main()
