"""The learner as ask/tell: one (method, run) of an experiment, driven by the caller's loop."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple, Union

import numpy as np
import numpy.typing as npt

from acps import _native

#: The kinds of tasks, by the code ``ask`` returns: a training rollout (explorative
#: parameters, its return feeds the policy), an evaluation of the greedy policy on a test
#: context, and a first visit of a training context (the greedy policy's baseline return).
KINDS = ("train", "evaluate", "baseline")

Settings = Union[str, "os.PathLike[str]", Mapping[str, Any]]
"""An experiment or problem file's path, or a dict of the same keys."""


@dataclass(frozen=True)
class Tasks:
    """A batch of tasks, one row per task: perform each with its ``thetas`` row in its
    ``contexts`` row (and its ``seeds`` entry for anything random), then ``tell`` the outcomes
    under its ``ids``."""

    ids: npt.NDArray[np.uint64]
    """Task ids, ``(n,)``."""
    kinds: npt.NDArray[np.str_]
    """``"train"``, ``"evaluate"`` or ``"baseline"`` per task, ``(n,)``."""
    seeds: npt.NDArray[np.uint64]
    """The seed of everything random inside each rollout, ``(n,)``."""
    contexts: npt.NDArray[np.float64]
    """The contexts, ``(n, n_s)``."""
    thetas: npt.NDArray[np.float64]
    """The low-level policy parameters, ``(n, n_theta)``."""

    def __len__(self) -> int:
        return len(self.ids)


class Evaluation(NamedTuple):
    """An evaluation of the greedy policy on the problem's test contexts."""

    episode: int
    """Training episodes consumed before it."""
    score: float | None
    """The problem's aggregate score; ``None`` while incomplete or when every rollout failed."""
    failed: int
    """Its failed rollouts, left out of the score."""


class Learner:
    """One learner of an experiment: the method ``method`` (the only one when ``None``) and
    run ``run`` (seed ``seed + run``) of the experiment or problem file ``settings``, exactly as
    ``acps run`` runs that job. Same settings, same outcomes, same bits: whatever the batch
    sizes of ``ask`` and the order of ``tell``.

    >>> learner = Learner("experiments/bowl.toml", method="random")  # doctest: +SKIP
    >>> while not learner.done:  # doctest: +SKIP
    ...     tasks = learner.ask(64)
    ...     rewards, scores = my_simulator(tasks.contexts, tasks.thetas)
    ...     learner.tell(tasks.ids, rewards, scores)

    ``ask`` returns what is ready, up to ``n``: the learner updates its policy after every
    ``in_flight`` training episodes (the experiment's setting), so at most that many training
    tasks (and an evaluation's) are out at once. A wider ``in_flight`` allows larger batches
    and changes the algorithm (its results differ), so choose it knowingly.

    Raises :class:`acps.SettingsError` for settings acps refuses, naming the key and its range.
    """

    def __init__(self, settings: Settings, *, method: str | None = None, run: int = 0) -> None:
        if isinstance(settings, Mapping):
            self._native = _native.NativeLearner.from_json(
                json.dumps(settings), "settings (a dict)", method, run
            )
        else:
            self._native = _native.NativeLearner.from_path(os.fspath(settings), method, run)
        experiment, method_name, run_index, runs = self._native.identity
        self.experiment: str = experiment
        """The experiment's (or the problem's) name."""
        self.method: str = method_name
        """The method's name."""
        self.run: int = run_index
        """The run's index, ``0 <= run < runs``."""
        self.runs: int = runs
        """The experiment's runs."""
        seed, n_s, n_theta = self._native.sizes
        self.seed: int = seed
        """The run's seed (the experiment's ``seed`` plus ``run``)."""
        self.n_context: int = n_s
        """The length of a context."""
        self.n_theta: int = n_theta
        """The length of the policy's parameters (0 for a problem without a policy)."""

    def ask(self, n: int = 1) -> Tasks:
        """Up to ``n`` tasks: all the learner has ready, at most ``n``; fewer, or none, while
        the rest wait for outcomes of tasks out."""
        if n < 0:
            raise ValueError(f"ask: n must be >= 0, got {n}")
        ids, kinds, seeds, contexts, thetas = self._native.ask(n)
        return Tasks(ids, np.asarray(KINDS)[kinds], seeds, contexts, thetas)

    def tell(
        self,
        ids: npt.ArrayLike,
        rewards: npt.ArrayLike,
        scores: npt.ArrayLike,
        ok: npt.ArrayLike | None = None,
    ) -> None:
        """Take the outcomes of tasks ``ids``: each rollout's ``rewards`` entry (the return the
        learner maximises) and ``scores`` entry (the problem's measure, for its evaluations),
        and whether it succeeded (``ok``; a non-finite reward or score fails it too). A failed
        task is asked again once. In any order and any grouping: the learner consumes outcomes
        in task order. The whole batch is checked before any of it is taken
        (:class:`acps.TellError`). Ctrl-C during the policy update an outcome starts raises
        ``KeyboardInterrupt`` at once, with the outcomes before that one taken and the rest
        not: :meth:`save` then continues the run bit for bit."""
        self._native.tell(
            np.ascontiguousarray(ids, dtype=np.uint64),
            np.ascontiguousarray(rewards, dtype=np.float64),
            np.ascontiguousarray(scores, dtype=np.float64),
            None if ok is None else np.ascontiguousarray(ok, dtype=np.bool_),
        )

    @property
    def done(self) -> bool:
        """Whether every training episode and evaluation has been consumed."""
        return self._native.done

    @property
    def episodes(self) -> int:
        """Training episodes consumed."""
        return self._native.episodes[0]

    @property
    def total_episodes(self) -> int:
        """Training episodes of the whole run."""
        return self._native.episodes[1]

    @property
    def tasks_in_flight(self) -> int:
        """Tasks handed out or ready whose outcomes have not been consumed."""
        return self._native.tasks_in_flight

    @property
    def evaluations(self) -> list[Evaluation]:
        """Every evaluation so far, the last possibly incomplete."""
        return [Evaluation(*e) for e in self._native.evaluations]

    @property
    def score(self) -> float | None:
        """The score of the latest complete evaluation that has one."""
        scored = [e.score for e in self.evaluations if e.score is not None]
        return scored[-1] if scored else None

    @property
    def training_contexts(self) -> npt.NDArray[np.float64]:
        """The problem's training contexts, ``(k, n_s)``."""
        return self._native.contexts(False)

    @property
    def test_contexts(self) -> npt.NDArray[np.float64]:
        """The problem's test contexts, ``(m, n_s)``: where evaluations roll out."""
        return self._native.contexts(True)

    def mean(self, contexts: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The greedy policy's parameters at each context: ``(m, n_theta)`` for contexts
        ``(m, n_s)``; a single context ``(n_s,)`` gives ``(n_theta,)``. Contexts of another
        length raise :class:`ValueError` naming both."""
        array = np.asarray(contexts, dtype=np.float64)
        if array.ndim == 1:
            means = self._native.mean(array.reshape(1, -1))
            return means.reshape(-1)
        return self._native.mean(array)

    def covariance(self) -> npt.NDArray[np.float64]:
        """The policy's covariance of the parameters, ``(n_theta, n_theta)``."""
        return self._native.covariance()

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the learner's whole state to ``path``, which :meth:`restore` continues from
        (:class:`acps.CheckpointError` when it cannot be written)."""
        self._native.save(os.fspath(path))

    def restore(self, path: str | os.PathLike[str]) -> None:
        """Continue from the checkpoint ``path`` of a learner of the same experiment, method
        and run; tasks that were out are asked again. Another job's, truncated or corrupted
        checkpoints raise :class:`acps.CheckpointError` naming the file, and so does a run
        directory's (continue those with ``acps run --resume`` or :func:`acps.run`)."""
        self._native.restore(os.fspath(path))

    def __repr__(self) -> str:
        return (
            f"Learner({self.experiment!r}, method={self.method!r}, run={self.run}: "
            f"{self.episodes}/{self.total_episodes} episodes)"
        )
