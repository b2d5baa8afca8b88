"""A whole experiment from Python: every (method, run) of a file, with your simulator."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Union

import numpy as np
import numpy.typing as npt

from acps import _native
from acps._learner import KINDS, Settings, Tasks

Floats = npt.NDArray[np.float64]

#: A per-task rollout: ``rollout(context, theta, seed)`` with the context ``(n_s,)`` and the
#: parameters ``(n_theta,)`` as arrays returns ``(reward, score)``, or ``None`` for a failed
#: rollout (raising stops the run).
Rollout = Callable[[Floats, Floats, int], Union[tuple[float, float], None]]
#: A batch rollout: ``batch_rollout(tasks)`` returns arrays ``(rewards, scores)`` or
#: ``(rewards, scores, ok)``, one entry per task.
BatchRollout = Callable[[Tasks], tuple[Any, ...]]


def run(
    settings: Settings,
    *,
    rollout: Rollout | None = None,
    batch_rollout: BatchRollout | None = None,
    out: str | os.PathLike[str] | None = None,
    quiet: bool = False,
    checkpoint_every: int = 10,
    resume: bool = False,
) -> Path:
    """Run every (method, run) of the experiment or problem file ``settings`` (a path, or a
    dict of the same keys) in this process and write the run directory ``acps run`` writes
    (``summary.json``, the tables, the pictures, the learned policies, checkpoints) into
    ``out`` (default ``runs/NAME``); returns it.

    With ``batch_rollout``, every task all jobs have ready goes to one call, as a
    :class:`Tasks` of numpy arrays (a vectorised simulator); with ``rollout``, one call per
    task; with neither, a paper experiment runs its own simulators. The results are those of
    ``acps run`` of the same file, bit for bit. Progress shows on stderr (a live line on a
    terminal, a plain line every 5 s otherwise; ``quiet`` hides it). Ctrl-C, or an exception of
    your function, stops the run after every unfinished job wrote its checkpoint
    (``checkpoint_every`` learning rounds apart; 0 writes none) and is raised here;
    ``resume=True`` continues from them.

    Raises :class:`acps.SettingsError` for settings acps refuses and :class:`acps.AcpsError`
    when the run fails (for example when every rollout of a job failed).
    """
    if rollout is not None and batch_rollout is not None:
        raise TypeError("run takes rollout or batch_rollout, not both")
    perform: _native.Perform | None = None
    if batch_rollout is not None:
        perform = _batched(batch_rollout)
    elif rollout is not None:
        perform = _batched(_one_by_one(rollout))
    path, text = (
        (None, json.dumps(settings))
        if isinstance(settings, Mapping)
        else (
            os.fspath(settings),
            None,
        )
    )
    done = _native.run(
        path,
        text,
        "settings (a dict)",
        None if out is None else os.fspath(out),
        perform,
        quiet,
        checkpoint_every,
        resume,
    )
    return Path(done)


def _outcomes(result: Any, n: int) -> tuple[Floats, Floats, npt.NDArray[np.bool_]]:
    """A batch's result as float rewards, float scores and the ok mask, checked."""
    if not isinstance(result, tuple) or len(result) not in (2, 3):
        raise TypeError(
            f"a batch rollout returns (rewards, scores) or (rewards, scores, ok), got {result!r}"
        )
    rewards = np.ascontiguousarray(result[0], dtype=np.float64).reshape(-1)
    scores = np.ascontiguousarray(result[1], dtype=np.float64).reshape(-1)
    ok = (
        np.ones(n, dtype=np.bool_)
        if len(result) == 2
        else np.ascontiguousarray(result[2], dtype=np.bool_).reshape(-1)
    )
    if not len(rewards) == len(scores) == len(ok) == n:
        raise ValueError(
            f"a batch rollout of {n} tasks returned {len(rewards)} rewards, {len(scores)} "
            f"scores and {len(ok)} ok flags"
        )
    return rewards, scores, ok


def _batched(batch_rollout: BatchRollout) -> _native.Perform:
    def perform(
        ids: npt.NDArray[np.uint64],
        kinds: npt.NDArray[np.uint32],
        seeds: npt.NDArray[np.uint64],
        contexts: Floats,
        thetas: Floats,
    ) -> tuple[Floats, Floats, npt.NDArray[np.bool_]]:
        tasks = Tasks(ids, np.asarray(KINDS)[kinds], seeds, contexts, thetas)
        return _outcomes(batch_rollout(tasks), len(ids))

    return perform


def _one_by_one(rollout: Rollout) -> BatchRollout:
    """``rollout`` called task by task, as a batch rollout."""

    def batch_rollout(tasks: Tasks) -> tuple[Floats, Floats, npt.NDArray[np.bool_]]:
        n = len(tasks)
        rewards, scores = np.zeros(n), np.zeros(n)
        ok = np.zeros(n, dtype=np.bool_)
        for i in range(n):
            result = rollout(tasks.contexts[i], tasks.thetas[i], int(tasks.seeds[i]))
            if result is not None:
                rewards[i], scores[i] = result
                ok[i] = True
        return rewards, scores, ok

    return batch_rollout
