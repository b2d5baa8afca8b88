"""acps.Learner: ask/tell reproduces `acps run` bit for bit, whatever the batches and the order
of tells; checkpoints continue bit for bit; bad settings and bad outcomes are refused by name."""

from __future__ import annotations

import csv
import functools
import importlib.util
import os
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path
from types import ModuleType

import numpy as np
import numpy.typing as npt

import acps

ROOT = Path(__file__).resolve().parents[2]
BOWL_TOML = ROOT / "experiments" / "bowl.toml"
BOWL_WORKER = ROOT / "processes" / "worker" / "python" / "examples" / "bowl.py"

Floats = npt.NDArray[np.float64]


@functools.cache
def bowl_example() -> ModuleType:
    """processes/worker/python/examples/bowl.py as a module."""
    spec = importlib.util.spec_from_file_location("bowl_example", BOWL_WORKER)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def bowl(contexts: Floats, thetas: Floats) -> tuple[Floats, Floats]:
    """The example's arithmetic over rows: the bits of its per-task worker."""
    rewards, scores = bowl_example().bowl(contexts, thetas)
    return rewards, scores


def learn(learner: acps.Learner, rng: np.random.Generator, stop_at: int | None = None) -> None:
    """Drive `learner` with batches of random sizes, telling each batch in a random order and
    grouping, until it is done (or has consumed `stop_at` episodes)."""
    while not learner.done and (stop_at is None or learner.episodes < stop_at):
        tasks = learner.ask(int(rng.integers(1, 12)))
        if len(tasks) == 0:
            raise AssertionError(f"{learner}: nothing to ask and nothing out")
        rewards, scores = bowl(tasks.contexts, tasks.thetas)
        order = rng.permutation(len(tasks))
        for part in np.array_split(order, int(rng.integers(1, 4))):
            learner.tell(tasks.ids[part], rewards[part], scores[part])


def scores(learner: acps.Learner) -> list[tuple[int, float | None]]:
    return [(e.episode, e.score) for e in learner.evaluations]


class LearnerTest(unittest.TestCase):
    def test_ask_tell_reproduces_the_command_line_bit_for_bit(self) -> None:
        """`acps run` of bowl.toml with the Python bowl workers, and every (method, run) of the
        same file driven here with other batch sizes and tell orders: the same scores."""
        acps_command = Path(sys.executable).parent / "acps"
        self.assertTrue(acps_command.exists(), "pip install puts the acps command beside python")
        with tempfile.TemporaryDirectory() as out:
            subprocess.run(
                [
                    str(acps_command),
                    "run",
                    "--config",
                    str(BOWL_TOML),
                    "--out",
                    out,
                    "-q",
                    "--workers",
                    "2",
                    "--worker-command",
                    f"{sys.executable} {BOWL_WORKER}",
                ],
                check=True,
                timeout=600,
            )
            with open(Path(out) / "runs.csv", newline="") as f:
                rows = list(csv.DictReader(f))
        rng = np.random.default_rng(7)
        compared = 0
        for method in ("monotonic-progress", "random"):
            for run in (0, 1):
                learner = acps.Learner(BOWL_TOML, method=method, run=run)
                learn(learner, rng)
                expected = [
                    (int(r["episode"]), float(r["score"]))
                    for r in rows
                    if r["method"] == method and int(r["run"]) == run
                ]
                self.assertEqual(scores(learner), expected, f"{method} run {run}")
                compared += len(expected)
        self.assertEqual(compared, 4 * 9)

    def test_a_dict_is_a_file_and_the_policy_is_the_learnt_one(self) -> None:
        """A dict of the file's keys gives the file's learner; mean() is the greedy policy
        (the evaluation's parameters) and the covariance is symmetric positive definite."""
        import tomllib

        with open(BOWL_TOML, "rb") as f:
            settings = tomllib.load(f)
        from_dict = acps.Learner(settings, method="random", run=1)
        from_file = acps.Learner(BOWL_TOML, method="random", run=1)
        learn(from_dict, np.random.default_rng(1))
        learn(from_file, np.random.default_rng(2))
        self.assertEqual(scores(from_dict), scores(from_file))
        contexts = from_file.test_contexts
        self.assertEqual(contexts.shape, (4, 2))
        means = from_file.mean(contexts)
        self.assertEqual(means.shape, (4, 4))
        np.testing.assert_array_equal(from_file.mean(contexts[1]), means[1])
        # Near the bowl's bottom after 400 episodes: theta_i = s_(i mod 2) (i + 1) / 4.
        best = np.stack([contexts[:, i % 2] * (i + 1) / 4 for i in range(4)], axis=1)
        self.assertLess(float(np.abs(means - best).max()), 0.5)
        with self.assertRaises(ValueError) as wrong:
            from_file.mean(np.zeros((2, 3)))
        self.assertIn("contexts of 3 values, the problem's have 2", str(wrong.exception))
        covariance = from_file.covariance()
        np.testing.assert_array_equal(covariance, covariance.T)
        self.assertGreater(float(np.linalg.eigvalsh(covariance).min()), 0.0)

    def test_a_saved_learner_continues_bit_for_bit(self) -> None:
        whole = acps.Learner(BOWL_TOML, method="monotonic-progress")
        learn(whole, np.random.default_rng(3))
        first = acps.Learner(BOWL_TOML, method="monotonic-progress")
        learn(first, np.random.default_rng(4), stop_at=170)
        out = first.ask(3)  # tasks out at the save are asked again after the restore
        self.assertGreater(len(out), 0)
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "learner.ckpt"
            first.save(path)
            self.assertFalse(os.stat(path).st_mode & 0o002, "not writable by others")
            second = acps.Learner(BOWL_TOML, method="monotonic-progress")
            second.restore(path)
            learn(second, np.random.default_rng(5))
            self.assertEqual(scores(second), scores(whole))
            other = acps.Learner(BOWL_TOML, method="random")
            with self.assertRaises(acps.CheckpointError) as refused:
                other.restore(path)
            self.assertIn(str(path), str(refused.exception))
            path.write_bytes(path.read_bytes()[:-5])
            with self.assertRaises(acps.CheckpointError) as refused:
                second.restore(path)
            self.assertIn("truncated", str(refused.exception))

    def test_bad_settings_are_refused_by_name(self) -> None:
        cases: list[tuple[acps.Settings, dict[str, object], str]] = [
            (BOWL_TOML, {}, "choose one with method="),
            (BOWL_TOML, {"method": "round-robin"}, "method round-robin is not one of"),
            (BOWL_TOML, {"method": "random", "run": 2}, "run must be in 0..2"),
            (ROOT / "no-such.toml", {}, "no-such.toml: cannot read"),
            ({"methods": ["random"]}, {}, "experiment must be set"),
            ({"experiment": "toy"}, {}, "set `panel` (toy) or `n_s` (dims)"),
            ({"experiment": "function", "epsilon": -1.0}, {}, "epsilon must be a number in"),
        ]
        for settings, options, message in cases:
            with self.subTest(message=message):
                with self.assertRaises(acps.SettingsError) as refused:
                    acps.Learner(settings, **options)  # type: ignore[arg-type]
                self.assertIn(message, str(refused.exception))
                self.assertIsInstance(refused.exception, acps.AcpsError)

    def test_bad_outcomes_are_refused_and_nothing_of_the_batch_is_taken(self) -> None:
        learner = acps.Learner(BOWL_TOML, method="random")
        tasks = learner.ask(100)
        self.assertEqual(sorted(set(tasks.kinds)), ["evaluate", "train"])
        rewards, scores_ = bowl(tasks.contexts, tasks.thetas)
        refusals = [
            ((tasks.ids, rewards[:-1], scores_), "rewards"),
            ((tasks.ids[[0, 0]], rewards[:2], scores_[:2]), "appears twice"),
            (
                (np.append(tasks.ids, 10_000), np.append(rewards, 0), np.append(scores_, 0)),
                "task 10000",
            ),
        ]
        for arguments, message in refusals:
            with self.subTest(message=message):
                with self.assertRaises(acps.TellError) as refused:
                    learner.tell(*arguments)
                self.assertIn(message, str(refused.exception))
        learner.tell(tasks.ids, rewards, scores_)
        with self.assertRaises(acps.TellError):
            learner.tell(tasks.ids[:1], rewards[:1], scores_[:1])
        # The refused batches took nothing: the run goes on as one that never saw them.
        learn(learner, np.random.default_rng(6))
        clean = acps.Learner(BOWL_TOML, method="random")
        learn(clean, np.random.default_rng(8))
        self.assertEqual(scores(learner), scores(clean))

    def test_bad_calls_are_refused_by_name(self) -> None:
        learner = acps.Learner(BOWL_TOML, method="random")
        with self.assertRaises(ValueError) as negative:
            learner.ask(-1)
        self.assertIn("n must be >= 0, got -1", str(negative.exception))
        with tempfile.TemporaryDirectory() as d:
            missing = Path(d) / "none.ckpt"
            with self.assertRaises(acps.CheckpointError) as refused:
                learner.restore(missing)
            self.assertIn(f"{missing}: no such file", str(refused.exception))

    def test_a_failed_rollout_is_asked_again_once(self) -> None:
        learner = acps.Learner(BOWL_TOML, method="random")
        tasks = learner.ask(100)
        rewards, scores_ = bowl(tasks.contexts, tasks.thetas)
        failed = np.zeros(len(tasks), dtype=bool)
        failed[-1] = True
        learner.tell(tasks.ids, rewards, scores_, ok=~failed)
        again = learner.ask(100)
        (where,) = np.flatnonzero(again.ids == tasks.ids[-1])
        np.testing.assert_array_equal(again.thetas[where], tasks.thetas[-1])
        learner.tell(again.ids, *bowl(again.contexts, again.thetas))
        self.assertNotIn(tasks.ids[-1], learner.ask(100).ids)


if __name__ == "__main__":
    unittest.main()
