"""acps.run: a whole experiment in this process writes `acps run`'s run directory bit for bit,
with a batch rollout, a per-task rollout or a paper experiment's own simulators; an exception
of the rollout stops the run with checkpoints that resume to the same bytes."""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from test_learner import BOWL_TOML, BOWL_WORKER, bowl

import acps

TABLES = ("summary.json", "runs.csv", "curves.csv", "selections.csv", "updates.csv")


def acps_command(*args: str) -> None:
    """The installed `acps` command with `args`, quiet."""
    acps_bin = Path(sys.executable).parent / "acps"
    subprocess.run([str(acps_bin), *args, "-q"], check=True, timeout=600)


def tables(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in TABLES}


def batch_bowl(tasks: acps.Tasks) -> tuple[Any, Any]:
    return bowl(tasks.contexts, tasks.thetas)


def one_bowl(context: Any, theta: Any, seed: int) -> tuple[float, float]:
    rewards, scores = bowl(context[None, :], theta[None, :])
    return float(rewards[0]), float(scores[0])


class RunTest(unittest.TestCase):
    reference: dict[str, bytes]

    @classmethod
    def setUpClass(cls) -> None:
        """The bowl file through `acps run` with two Python bowl workers."""
        with tempfile.TemporaryDirectory() as out:
            acps_command(
                "run",
                "--config",
                str(BOWL_TOML),
                "--out",
                out,
                "--workers",
                "2",
                "--worker-command",
                f"{sys.executable} {BOWL_WORKER}",
            )
            cls.reference = tables(Path(out))

    def test_batch_and_per_task_rollouts_write_the_command_lines_run_directory(self) -> None:
        for name, options in (
            ("batch", {"batch_rollout": batch_bowl}),
            ("one", {"rollout": one_bowl}),
        ):
            with self.subTest(name), tempfile.TemporaryDirectory() as d:
                out = acps.run(BOWL_TOML, out=Path(d) / "bowl", quiet=True, **options)
                self.assertEqual(out, Path(d) / "bowl")
                self.assertEqual(tables(out), self.reference)
                self.assertTrue((out / "curves.png").is_file())
                self.assertEqual(len(list((out / "policies").iterdir())), 4)

    def test_a_finished_run_is_replaced_only_when_asked(self) -> None:
        with tempfile.TemporaryDirectory() as d:
            out = acps.run(BOWL_TOML, batch_rollout=batch_bowl, out=Path(d) / "bowl", quiet=True)
            (out / "mine.txt").write_text("kept")
            with self.assertRaisesRegex(acps.SettingsError, "holds a finished run .*--force"):
                acps.run(BOWL_TOML, batch_rollout=batch_bowl, out=out, quiet=True)
            self.assertEqual(tables(out), self.reference)
            acps.run(BOWL_TOML, batch_rollout=batch_bowl, out=out, quiet=True, force=True)
            self.assertEqual(tables(out), self.reference)
            self.assertEqual((out / "mine.txt").read_text(), "kept")

    def test_an_exception_stops_the_run_with_checkpoints_that_resume_to_the_same_bytes(
        self,
    ) -> None:
        calls = [0]

        def breaks(tasks: acps.Tasks) -> tuple[Any, Any]:
            calls[0] += 1
            if calls[0] == 60:
                raise RuntimeError("the simulator crashed")
            return batch_bowl(tasks)

        with tempfile.TemporaryDirectory() as d:
            out = Path(d) / "bowl"
            with self.assertRaises(RuntimeError):
                acps.run(BOWL_TOML, batch_rollout=breaks, out=out, quiet=True, checkpoint_every=1)
            checkpoints = sorted((out / "checkpoints").glob("*.ckpt"))
            self.assertTrue(checkpoints)
            self.assertFalse((out / "summary.json").exists())
            # A run's checkpoint keeps its records beside it: a lone learner refuses it.
            learner = acps.Learner(BOWL_TOML, method="monotonic-progress", run=0)
            with self.assertRaises(acps.CheckpointError) as refused:
                learner.restore(out / "checkpoints" / "monotonic-progress-run-0.ckpt")
            self.assertIn("acps run --resume", str(refused.exception))
            acps.run(BOWL_TOML, batch_rollout=batch_bowl, out=out, quiet=True, resume=True)
            self.assertEqual(tables(out), self.reference)

    def test_a_paper_experiment_runs_its_own_simulators_as_acps_experiment_does(self) -> None:
        settings = {"experiment": "function", "runs": 2, "episodes": 200, "methods": ["random"]}
        with tempfile.TemporaryDirectory() as d:
            acps_command(
                "experiment",
                "function",
                "--runs",
                "2",
                "--episodes",
                "200",
                "--method",
                "random",
                "--out",
                f"{d}/cli",
            )
            out = acps.run(settings, out=f"{d}/py", quiet=True)
            self.assertEqual(tables(out), tables(Path(d) / "cli"))

    def test_progress_reports_reach_a_callback_and_tqdm_bars_and_a_failing_one_stops_the_run(
        self,
    ) -> None:
        reports: list[acps.Progress] = []
        with tempfile.TemporaryDirectory() as d:
            out = acps.run(
                BOWL_TOML,
                batch_rollout=batch_bowl,
                out=Path(d) / "bowl",
                quiet=True,
                progress=reports.append,
            )
            # The callback changes nothing of the run.
            self.assertEqual(tables(out), self.reference)
        self.assertGreater(len(reports), 1)
        self.assertTrue(
            all(r.experiment == "bowl" and r.total == reports[0].total for r in reports)
        )
        episodes = [r.episodes for r in reports]
        self.assertEqual(episodes, sorted(episodes))
        self.assertEqual([r.done for r in reports], [False] * (len(reports) - 1) + [True])
        self.assertEqual(reports[-1].episodes, reports[-1].total)
        self.assertTrue(reports[-1].message.startswith("final "), reports[-1].message)

        class Bar:
            """The part of tqdm's interface TqdmBars uses, recording what it is told."""

            made: ClassVar[list[Bar]] = []

            def __init__(self, total: int, desc: str, unit: str) -> None:
                self.total, self.desc, self.n, self.postfix, self.closed = total, desc, 0, "", False
                Bar.made.append(self)

            def update(self, n: int) -> None:
                self.n += n

            def set_postfix_str(self, text: str, refresh: bool) -> None:
                self.postfix = text

            def close(self) -> None:
                self.closed = True

        bars = acps.TqdmBars(Bar)
        for report in reports:
            bars(report)
        [bar] = Bar.made
        self.assertEqual(
            (bar.desc, bar.n, bar.total, bar.closed), ("bowl", bar.total, bar.total, True)
        )
        self.assertEqual(bar.postfix, reports[-1].message)

        def fails(report: acps.Progress) -> None:
            raise KeyError("the log is full")

        with tempfile.TemporaryDirectory() as d:
            with self.assertRaises(KeyError):
                acps.run(BOWL_TOML, batch_rollout=batch_bowl, out=d, quiet=True, progress=fails)
            self.assertFalse((Path(d) / "summary.json").exists())

    def test_bad_arguments_and_bad_batches_are_refused(self) -> None:
        with self.assertRaises(TypeError):
            acps.run(BOWL_TOML, rollout=one_bowl, batch_rollout=batch_bowl)
        with tempfile.TemporaryDirectory() as d:
            with self.assertRaises(acps.SettingsError) as refused:
                acps.run({"experiment": "function", "runs": 0}, out=d)
            self.assertIn("runs", str(refused.exception))
            with self.assertRaises(ValueError) as short:
                acps.run(
                    BOWL_TOML,
                    batch_rollout=lambda tasks: (np.zeros(len(tasks) - 1), np.zeros(len(tasks))),
                    out=f"{d}/short",
                    quiet=True,
                )
            self.assertIn("returned", str(short.exception))
            with self.assertRaises(TypeError) as not_a_pair:
                acps.run(
                    BOWL_TOML,
                    batch_rollout=lambda tasks: [np.zeros(len(tasks))],  # type: ignore[arg-type, return-value]
                    out=f"{d}/list",
                    quiet=True,
                )
            self.assertIn(
                "returns (rewards, scores) or (rewards, scores, ok)", str(not_a_pair.exception)
            )

    def test_ctrl_c_stops_the_run_with_checkpoints(self) -> None:
        """SIGINT to a process inside acps.run: KeyboardInterrupt, after the checkpoints."""
        with tempfile.TemporaryDirectory() as d:
            started, out = Path(d) / "started", Path(d) / "long"
            # A process started in the background by a non-interactive shell inherits SIGINT
            # ignored, and Python then installs no handler: restore it, as a terminal has it.
            script = (
                "import signal, sys, pathlib, tomllib, acps\n"
                "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
                "sys.path.insert(0, sys.argv[1])\n"
                "from test_run import batch_bowl\n"
                "settings = tomllib.load(open(sys.argv[2], 'rb'))\n"
                "settings['episodes'] = 10_000_000\n"
                "def f(tasks):\n"
                "    pathlib.Path(sys.argv[3]).touch()\n"
                "    return batch_bowl(tasks)\n"
                "acps.run(settings, batch_rollout=f, out=sys.argv[4], quiet=True,"
                " checkpoint_every=1)\n"
            )
            tests = str(Path(__file__).parent)
            child = subprocess.Popen(
                [sys.executable, "-c", script, tests, str(BOWL_TOML), str(started), str(out)],
                stderr=subprocess.PIPE,
                text=True,
            )
            try:
                deadline = time.monotonic() + 120
                while not started.exists():
                    self.assertIsNone(child.poll(), "the run ended before its first batch")
                    self.assertLess(time.monotonic(), deadline, "no batch within 120 s")
                    time.sleep(0.01)
                child.send_signal(signal.SIGINT)
                _, stderr = child.communicate(timeout=120)
            finally:
                child.kill()
            self.assertNotEqual(child.returncode, 0)
            self.assertIn("KeyboardInterrupt", stderr)
            self.assertEqual(len(list((out / "checkpoints").glob("*.ckpt"))), 4)
            self.assertFalse((out / "summary.json").exists())

    def test_ctrl_c_stops_the_largest_update_that_tell_starts(self) -> None:
        """SIGINT while tell runs a self-paced C-REPS update of 100,000 rollouts of 64 parameters
        (about 1.3 s): KeyboardInterrupt from tell, that outcome not taken, and the learner goes
        on."""
        with tempfile.TemporaryDirectory() as d:
            telling = Path(d) / "telling"
            script = (
                "import signal, sys, pathlib, numpy as np, acps\n"
                "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
                "n = 100_000\n"
                "settings = {'methods': ['self-paced'], 'episodes': n, 'eval_every': n,\n"
                "    'in_flight': 1000, 'memory_size': n, 'update_every': n, 'memory': 'window',\n"
                "    'problem': {'name': 'wide', 'theta0': [0.0] * 64, 'metric': 'cost',\n"
                "        'training_grid': {'low': [0.0], 'high': [1.0], 'points': [5]},\n"
                "        'test_contexts': [[0.5]], 'environment': {'name': 'wide', 'settings': 'v1'}}}\n"
                "learner = acps.Learner(settings, method='self-paced')\n"
                "def outcomes(tasks):\n"
                "    rewards = -np.sum(tasks.thetas**2, axis=1)\n"
                "    return tasks.ids, rewards, -rewards\n"
                "issued, last = 0, None\n"
                "while last is None:\n"
                "    tasks = learner.ask(1000)\n"
                "    training = np.flatnonzero(tasks.kinds == 'train')\n"
                "    ids, rewards, scores = outcomes(tasks)\n"
                "    keep = np.ones(len(tasks), dtype=bool)\n"
                "    if issued + len(training) == n:\n"
                "        keep[training[-1]] = False\n"
                "        last = tuple(a[~keep] for a in (ids, rewards, scores))\n"
                "    issued += len(training)\n"
                "    learner.tell(ids[keep], rewards[keep], scores[keep])\n"
                "pathlib.Path(sys.argv[1]).touch()\n"
                "try:\n"
                "    learner.tell(*last)\n"
                "    print('the update ran to its end')\n"
                "except KeyboardInterrupt:\n"
                "    print('interrupted at', learner.episodes)\n"
                "learner.tell(*last)\n"
                "print('then', learner.episodes)\n"
            )
            child = subprocess.Popen(
                [sys.executable, "-c", script, str(telling)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            try:
                deadline = time.monotonic() + 120
                while not telling.exists():
                    self.assertIsNone(child.poll(), "the learner ended before its last tell")
                    self.assertLess(time.monotonic(), deadline, "no last tell within 120 s")
                    time.sleep(0.01)
                child.send_signal(signal.SIGINT)
                stdout, stderr = child.communicate(timeout=120)
            finally:
                child.kill()
            self.assertEqual(child.returncode, 0, stderr)
            self.assertEqual(stdout.split("\n")[:2], ["interrupted at 99999", "then 100000"])


if __name__ == "__main__":
    unittest.main()
