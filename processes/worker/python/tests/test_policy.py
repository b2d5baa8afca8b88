"""Policy files: reading, checking and the mean's arithmetic (the comparison with Rust's own
numbers is the launcher's test `python::policy_means_are_rusts_bit_for_bit`)."""

from __future__ import annotations

import json
import tempfile
import unittest
from pathlib import Path
from typing import Any

from acps_worker import Environment, Policy


def policy(features: str, context_dim: int, weights: list[list[float]]) -> dict[str, Any]:
    """A policy file's JSON."""
    n = len(weights[0])
    return {
        "format": "acps-policy-2",
        "experiment": "test",
        "method": "random",
        "run": 0,
        "seed": 3,
        "problem": {
            "test_contexts": [[0.5] * context_dim],
            "environment": {
                "name": "bowl",
                "settings": "00000000000000ff",
                "parameters": [1, 2, 3],
            },
        },
        "policy": {
            "features": features,
            "context_dim": context_dim,
            "weights": weights,
            "covariance": [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)],
        },
    }


class PolicyTest(unittest.TestCase):
    """W^T phi(s) for the built-in feature maps, and errors naming the field."""

    def test_affine_mean(self) -> None:
        """phi = [s, 1]."""
        p = Policy(policy("affine", 1, [[2.0, 3.0], [1.0, -1.0]]))
        self.assertEqual(p.mean([2.0]), [5.0, 5.0])
        self.assertEqual(p.environment, Environment("bowl", 0xFF, (1, 2, 3)))

    def test_quadratic_features_are_ordered_like_rusts(self) -> None:
        """s0^2, s0 s1, s1^2, s0, s1, 1: one weight column picks each feature."""
        identity = [[1.0 if i == j else 0.0 for j in range(6)] for i in range(6)]
        p = Policy(policy("quadratic", 2, identity))
        self.assertEqual(p.mean([2.0, -3.0]), [4.0, -6.0, 9.0, 2.0, -3.0, 1.0])

    def test_long_dot_products_sum_in_nalgebras_order(self) -> None:
        """Ten features: eight accumulators summed pairwise (0+4, 1+5, ...), then the rest;
        left-to-right summation would lose the 1 to 1e16 and give 0."""
        column = [1e16, 1.0, 0.0, 0.0, -1e16, 0.0, 0.0, 0.0, 0.0, 0.0]
        p = Policy(policy("quadratic", 3, [[w] for w in column]))
        self.assertEqual(p.mean([1.0, 1.0, 1.0]), [1.0])

    def test_polar_features(self) -> None:
        """r = |s|, a = atan2(s1, s0): [r^2, r a, a^2, r, a, 1]."""
        identity = [[1.0 if i == j else 0.0 for j in range(6)] for i in range(6)]
        r, a = Policy(policy("polar-quadratic", 2, identity)).mean([-3.0, 4.0])[3:5]
        self.assertEqual(r, 5.0)
        self.assertAlmostEqual(a, 2.214297435588181, places=15)

    def test_bad_files_are_refused_naming_the_field(self) -> None:
        """Format, features, shapes, finiteness, context length."""
        cases = [
            ({"format": "acps-policy-1"}, "format must be 'acps-policy-2'"),
            (policy("cubic", 1, [[1.0], [1.0]]), "features must be one of"),
            (policy("affine", 1, [[1.0]]), "weights: must have 2 rows"),
            (policy("affine", 1, [[1.0], [1.0, 2.0]]), "row 1 has 2"),
            # A short first row is blamed itself: theta0 says how long rows are.
            (
                {**policy("affine", 1, [[1.0], [1.0, 2.0]]), "problem": {"theta0": [0.0, 0.0]}},
                r"must have 2 entries \(n_theta\), row 0 has 1",
            ),
            (policy("affine", 1, [[1.0], [float("nan")]]), "must be finite"),
            (policy("polar-quadratic", 3, [[1.0]] * 6), "exactly 2"),
        ]
        for data, message in cases:
            with self.subTest(message=message), self.assertRaisesRegex(ValueError, message):
                Policy(data)
        with self.assertRaisesRegex(ValueError, "context has 2 values"):
            Policy(policy("affine", 1, [[1.0], [1.0]])).mean([1.0, 2.0])

    def test_load_reads_a_run_directory(self) -> None:
        """The first method's file of run 0, or the one named."""
        with tempfile.TemporaryDirectory() as directory:
            files = Path(directory) / "policies"
            files.mkdir()
            for method, weight in [("b-method", 2.0), ("a-method", 1.0)]:
                data = policy("affine", 1, [[weight], [0.0]])
                (files / f"{method}-run0.json").write_text(json.dumps(data))
            self.assertEqual(Policy.load(directory).mean([1.0]), [1.0])
            self.assertEqual(Policy.load(directory, method="b-method").mean([1.0]), [2.0])
            with self.assertRaisesRegex(FileNotFoundError, "no policy file of run 1"):
                Policy.load(directory, run=1)
            # A file outside policies/ is not reached through the method's name.
            outside = policy("affine", 1, [[9.0], [0.0]])
            (Path(directory) / "x-run0.json").write_text(json.dumps(outside))
            with self.assertRaisesRegex(FileNotFoundError, "its methods: a-method, b-method"):
                Policy.load(directory, method="../x")


if __name__ == "__main__":
    unittest.main()
