"""Learned policies of a run directory (``policies/METHOD-runR.json``, format
``acps-policy-2``, written by ``processes/launcher/experiments/src/records.rs``): the mean
``W^T phi(s)`` computed with the same floating-point operations, in the same order, as the Rust
learner (``processes/learner/src/creps/features.rs`` and nalgebra's ``tr_mul``), so the bits
agree."""

from __future__ import annotations

import ctypes
import ctypes.util
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .environment import Environment

#: The policy file format this reader understands.
POLICY_FORMAT = "acps-policy-2"
#: The directory of the policy files inside a run directory.
POLICY_DIR = "policies"
FEATURES = ("affine", "quadratic", "polar-quadratic")

_libm = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")
# Rust's f64::hypot and f64::atan2 call the C library's; Python's math.hypot has its own
# algorithm, which may round differently.
_libm.hypot.restype = ctypes.c_double
_libm.hypot.argtypes = (ctypes.c_double, ctypes.c_double)
_libm.atan2.restype = ctypes.c_double
_libm.atan2.argtypes = (ctypes.c_double, ctypes.c_double)


def feature_count(features: str, context_dim: int) -> int:
    """The number of features of the map ``features`` for ``context_dim``-dimensional contexts."""
    if features == "affine":
        return context_dim + 1
    if features == "quadratic":
        return context_dim * (context_dim + 1) // 2 + context_dim + 1
    if features == "polar-quadratic":
        return 6
    raise ValueError(f"features must be one of {FEATURES}, got {features!r}")


def _quadratic(x: Sequence[float]) -> list[float]:
    """``[x_i x_j for i <= j] ++ x ++ [1]``."""
    out = [x[i] * x[j] for i in range(len(x)) for j in range(i, len(x))]
    out.extend(x)
    out.append(1.0)
    return out


def features_of(features: str, context: Sequence[float]) -> list[float]:
    """phi(s) of the map ``features`` (affine, quadratic or polar-quadratic)."""
    s = [float(v) for v in context]
    if features == "affine":
        return s + [1.0]
    if features == "quadratic":
        return _quadratic(s)
    if features == "polar-quadratic":
        radius = float(_libm.hypot(s[0], s[1]))
        angle = float(_libm.atan2(s[1], s[0]))
        return _quadratic([radius, angle])
    raise ValueError(f"features must be one of {FEATURES}, got {features!r}")


def _dot(column: Sequence[float], phi: Sequence[float]) -> float:
    """nalgebra's dot product of dynamically sized vectors: eight accumulators over blocks of
    eight, summed pairwise into the result, then the rest in order."""
    n = len(phi)
    acc = [0.0] * 8
    i = 0
    while n - i >= 8:
        for k in range(8):
            acc[k] += column[i + k] * phi[i + k]
        i += 8
    res = 0.0
    res += acc[0] + acc[4]
    res += acc[1] + acc[5]
    res += acc[2] + acc[6]
    res += acc[3] + acc[7]
    for k in range(i, n):
        res += column[k] * phi[k]
    return res


def _matrix(data: Any, field: str, rows: int, columns: int) -> list[list[float]]:
    """A checked ``rows`` x ``columns`` matrix of finite floats from row lists."""
    if not isinstance(data, list) or len(data) != rows:
        got = len(data) if isinstance(data, list) else type(data).__name__
        raise ValueError(f"policy {field}: must have {rows} rows, got {got}")
    if columns == 0:
        raise ValueError(f"policy {field}: rows must not be empty")
    out: list[list[float]] = []
    for i, row in enumerate(data):
        if not isinstance(row, list) or len(row) != columns:
            raise ValueError(
                f"policy {field}: every row must have {columns} entries (n_theta), row {i} has "
                f"{len(row) if isinstance(row, list) else row!r}"
            )
        values = []
        for j, value in enumerate(row):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(  # noqa: TRY004 - a bad file, as every other check here
                    f"policy {field}: entry at row {i}, column {j} is {value!r}"
                )
            if not math.isfinite(value):
                raise ValueError(
                    f"policy {field}: entries must be finite, got {value} at row {i}, column {j}"
                )
            values.append(float(value))
        out.append(values)
    return out


class Policy:
    """A learned C-REPS policy: the linear Gaussian ``N(W^T phi(s), Sigma)`` and the problem
    it was learnt for."""

    def __init__(self, data: dict[str, Any], source: str = "policy") -> None:
        """A policy from the parsed JSON of a policy file (``source`` names it in errors)."""
        fmt = data.get("format") if isinstance(data, dict) else None
        if fmt != POLICY_FORMAT:
            raise ValueError(f"{source}: format must be {POLICY_FORMAT!r}, got {fmt!r}")
        try:
            policy = data["policy"]
            self.features: str = policy["features"]
            self.context_dim: int = int(policy["context_dim"])
            weights, covariance = policy["weights"], policy["covariance"]
        except (KeyError, TypeError) as error:
            raise ValueError(f"{source}: not an acps policy file (missing {error})") from error
        if self.features not in FEATURES:
            raise ValueError(
                f"{source}: policy features must be one of {FEATURES}, got {self.features!r}"
            )
        if self.features == "polar-quadratic" and self.context_dim != 2:
            raise ValueError(
                f"{source}: policy context_dim must be exactly 2 for the polar-quadratic "
                f"feature map, got {self.context_dim}"
            )
        if self.context_dim < 1:
            raise ValueError(f"{source}: policy context_dim must be >= 1, got {self.context_dim}")
        n_phi = feature_count(self.features, self.context_dim)
        # The problem's initial parameters say how many there are, so that a short row is
        # blamed itself rather than the rows after it.
        theta0 = (data.get("problem") or {}).get("theta0")
        first = weights[0] if isinstance(weights, list) and weights else None
        self.n_theta = len(theta0) if isinstance(theta0, list) else len(first or [])
        try:
            self.weights = _matrix(weights, "weights", n_phi, self.n_theta)
            self.covariance = _matrix(covariance, "covariance", self.n_theta, self.n_theta)
        except ValueError as error:
            raise ValueError(f"{source}: {error}") from error
        # Columns of W, one per parameter: the vectors nalgebra's tr_mul dots with phi.
        self._columns = [[row[j] for row in self.weights] for j in range(self.n_theta)]
        self.experiment: str | None = data.get("experiment")
        self.method: str | None = data.get("method")
        self.run: int | None = data.get("run")
        self.seed: int | None = data.get("seed")
        problem = data.get("problem") or {}
        self.test_contexts: list[list[float]] = problem.get("test_contexts", [])
        self.training_contexts: list[list[float]] = problem.get("training_contexts", [])
        self.environment: Environment | None = None
        env = problem.get("environment")
        if env is not None:
            self.environment = Environment(
                env["name"], int(env["settings"], 16), tuple(env["parameters"])
            )

    @classmethod
    def load(
        cls,
        path: str | Path,
        method: str | None = None,
        run: int = 0,
    ) -> Policy:
        """Read a policy file, or the file of ``method`` (default: the first by name) and
        ``run`` in the run directory ``path``."""
        path = Path(path)
        if path.is_dir():
            directory = path / POLICY_DIR
            if not directory.is_dir():
                raise FileNotFoundError(f"{path} has no {POLICY_DIR}/ directory")
            suffix = f"-run{run}.json"
            # Only the files the directory lists: a method cannot name a path outside it.
            methods = sorted(
                p.name[: -len(suffix)] for p in directory.glob(f"*{suffix}") if p.is_file()
            )
            if not methods:
                raise FileNotFoundError(f"{directory} holds no policy file of run {run}")
            if method is None:
                method = methods[0]
            elif method not in methods:
                raise FileNotFoundError(
                    f"{directory} holds no policy of method {method!r} in run {run}; "
                    f"its methods: {', '.join(methods)}"
                )
            path = directory / f"{method}{suffix}"
        text = path.read_text(encoding="utf-8")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise ValueError(f"{path}: not an acps policy file ({error})") from error
        return cls(data, source=str(path))

    def mean(self, context: Sequence[float]) -> list[float]:
        """The mean parameters ``W^T phi(context)`` (exploration off), bit for bit as Rust's
        ``RestoredPolicy::greedy``."""
        if len(context) != self.context_dim:
            raise ValueError(
                f"context has {len(context)} values, the policy's context_dim is {self.context_dim}"
            )
        phi = features_of(self.features, context)
        return [_dot(column, phi) for column in self._columns]
