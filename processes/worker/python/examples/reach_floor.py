"""The policy class's floor on mujoco_reach.py's problem (docs/RESULTS.md).

Per training target of mujoco_reach.toml, theta is optimised by Nelder-Mead on the mean return over
8 start perturbations; the quadratic policy theta(s) = W^T phi(s) is fitted to those optima by least
squares and measured greedily on the test targets, each over 8 other perturbations. What a learner
of that policy class can reach at best::

    python processes/worker/python/examples/reach_floor.py
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
from mujoco_reach import rollout

import acps_worker

Vector = npt.NDArray[np.float64]
TRAINING = ((0.3, -0.2), (0.7, 0.4), (4, 4))
TEST = ((0.35, -0.15), (0.65, 0.35), (3, 3))
THETA0 = (0.5, 1.0, 0.5, 1.0)


def outcome(theta: Vector, target: Sequence[float], seed: int) -> tuple[float, float]:
    """The return and the distance in cm of one reach."""
    task = acps_worker.Task(
        id=0,
        job=0,
        kind="train",
        seed=seed,
        context=tuple(target),
        theta=tuple(float(t) for t in theta),
    )
    return rollout(task)


def mean_return(theta: Vector, target: Sequence[float]) -> float:
    return float(np.mean([outcome(theta, target, seed)[0] for seed in range(8)]))


def mean_distance(theta: Vector, target: Sequence[float]) -> float:
    return float(np.mean([outcome(theta, target, 100 + seed)[1] for seed in range(8)]))


def nelder_mead(cost: Callable[[Vector], float], start: Vector, step: float) -> Vector:
    """400 iterations of Nelder-Mead from a simplex of `step` around `start`."""
    n = len(start)
    points = [start] + [start + step * np.eye(n)[i] for i in range(n)]
    values = [cost(p) for p in points]
    for _ in range(400):
        order = np.argsort(values)
        points = [points[i] for i in order]
        values = [values[i] for i in order]
        centre = np.mean(points[:-1], axis=0)
        reflected = centre + (centre - points[-1])
        reflected_value = cost(reflected)
        if reflected_value < values[0]:
            expanded = centre + 2.0 * (centre - points[-1])
            expanded_value = cost(expanded)
            if expanded_value < reflected_value:
                points[-1], values[-1] = expanded, expanded_value
            else:
                points[-1], values[-1] = reflected, reflected_value
        elif reflected_value < values[-2]:
            points[-1], values[-1] = reflected, reflected_value
        else:
            contracted = centre + 0.5 * (points[-1] - centre)
            contracted_value = cost(contracted)
            if contracted_value < values[-1]:
                points[-1], values[-1] = contracted, contracted_value
            else:
                points = [points[0] + 0.5 * (p - points[0]) for p in points]
                values = [cost(p) for p in points]
    best: Vector = points[int(np.argmin(values))]
    return best


def grid(
    spec: tuple[tuple[float, float], tuple[float, float], tuple[int, int]],
) -> list[list[float]]:
    low, high, counts = spec
    axes = [np.linspace(lo, hi, k) for lo, hi, k in zip(low, high, counts, strict=True)]
    return [[float(x) for x in point] for point in itertools.product(*axes)]


def features(target: Sequence[float]) -> Vector:
    x, y = target
    return np.array([x * x, x * y, y * y, x, y, 1.0])


def main() -> None:
    optima = []
    for target in grid(TRAINING):

        def cost(theta: Vector, target: list[float] = target) -> float:
            return -mean_return(theta, target)

        best = nelder_mead(cost, np.array(THETA0), 0.3)
        best = nelder_mead(cost, best, 0.05)
        optima.append(best)
        print(f"target {target}: {mean_distance(best, target):.2f} cm", flush=True)
    phi = np.array([features(t) for t in grid(TRAINING)])
    weights, *_ = np.linalg.lstsq(phi, np.array(optima), rcond=None)
    per_target = np.mean([mean_distance(o, t) for o, t in zip(optima, grid(TRAINING), strict=True)])
    fitted = np.mean([mean_distance(weights.T @ features(t), t) for t in grid(TEST)])
    print(f"per-target optima on the training targets: mean {per_target:.2f} cm")
    print(f"the quadratic policy fitted to them, on the test targets: mean {fitted:.2f} cm")


if __name__ == "__main__":
    main()
