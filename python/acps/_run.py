"""A whole experiment from Python: every (method, run) of a file, with your simulator."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Progress:
    """Where a running experiment is, as :func:`run` reports it to a ``progress`` callback."""

    experiment: str
    """The experiment's name."""
    episodes: int
    """Training episodes done, over all its (method, run) jobs."""
    total: int
    """Training episodes in all."""
    message: str
    """The latest test score and rollouts per second; once done, the final score."""
    done: bool
    """Whether the experiment is done (its last report)."""


def run(
    settings: Settings,
    *,
    rollout: Rollout | None = None,
    batch_rollout: BatchRollout | None = None,
    out: str | os.PathLike[str] | None = None,
    quiet: bool = False,
    checkpoint_every: int = 10,
    resume: bool = False,
    force: bool = False,
    progress: Callable[[Progress], None] | None = None,
) -> Path:
    """Run every (method, run) of the experiment or problem file ``settings`` (a path, or a
    dict of the same keys) in this process and write the run directory ``acps run`` writes
    (``summary.json``, the tables, the pictures, the learned policies, checkpoints) into
    ``out`` (default ``runs/NAME``); returns it.

    With ``batch_rollout``, every task all jobs have ready goes to one call, as a
    :class:`Tasks` of numpy arrays (a vectorised simulator); with ``rollout``, one call per
    task; with neither, a paper experiment runs its own simulators. The results are those of
    ``acps run`` of the same file, bit for bit. Progress shows on stderr (a live line on a
    terminal, a plain line every 5 s otherwise), or as a tqdm bar in a Jupyter notebook (with
    tqdm installed); ``quiet`` hides it. ``progress`` is called with a :class:`Progress` at most
    every 0.1 s and once when an experiment is done (your own log or bar; it is called from the
    threads that run the jobs). Ctrl-C, or an exception of your function or of ``progress``,
    stops the run after every unfinished job wrote its checkpoint
    (``checkpoint_every`` learning rounds apart; 0 writes none) and is raised here;
    ``resume=True`` continues from them. A directory that holds a finished run (its
    ``summary.json``) is refused unless ``force=True``, which replaces its results.

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
    line = True
    if progress is None and not quiet:
        progress = _notebook_bars()
        line = progress is None
    done = _native.run(
        path,
        text,
        "settings (a dict)",
        None if out is None else os.fspath(out),
        perform,
        quiet,
        checkpoint_every,
        resume,
        force,
        None if progress is None else _reporting(progress),
        line,
    )
    return Path(done)


def _reporting(progress: Callable[[Progress], None]) -> Callable[[str, int, int, str, bool], None]:
    """``progress`` as the extension calls it."""

    def report(experiment: str, episodes: int, total: int, message: str, done: bool) -> None:
        progress(Progress(experiment, episodes, total, message, done))

    return report


def _in_notebook() -> bool:
    """Whether this runs in a Jupyter kernel, whose cells do not show a terminal's live line."""
    shell = sys.modules.get("IPython")
    get_ipython = getattr(shell, "get_ipython", None)
    if get_ipython is None:
        return False
    ipython = get_ipython()
    return ipython is not None and type(ipython).__name__ == "ZMQInteractiveShell"


def _notebook_bars() -> Callable[[Progress], None] | None:
    """In a Jupyter notebook with tqdm installed, a tqdm bar per experiment; else ``None`` (the
    extension's own line on stderr)."""
    if not _in_notebook():
        return None
    try:
        from tqdm.auto import tqdm  # type: ignore[import-untyped, unused-ignore]
    except ImportError:
        return None
    return TqdmBars(tqdm)


class TqdmBars:
    """Progress reports drawn as one bar per experiment by ``tqdm`` (a tqdm class: the notebook
    one in Jupyter)."""

    def __init__(self, tqdm: Any) -> None:
        """Bars of the class ``tqdm``."""
        self.tqdm = tqdm
        self.bars: dict[str, Any] = {}

    def __call__(self, report: Progress) -> None:
        """Move the experiment's bar to ``report``; close it when it is done."""
        bar = self.bars.get(report.experiment)
        if bar is None:
            bar = self.tqdm(total=report.total, desc=report.experiment, unit="episodes")
            self.bars[report.experiment] = bar
        bar.total = report.total
        bar.update(report.episodes - bar.n)
        bar.set_postfix_str(report.message, refresh=False)
        if report.done:
            bar.close()
            del self.bars[report.experiment]


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
