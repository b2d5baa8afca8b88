"""Batches for vectorised simulators: the tasks a worker holds, as numpy arrays, go to one call
of the user's ``batch_rollout``, and its arrays of rewards and scores come back into the
outcomes of the worker's next request without a Python loop over tasks."""

from __future__ import annotations

import ctypes
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _wire

#: Task kinds by wire code, as an array for indexing by code.
_KINDS = np.array(["train", "evaluate", "baseline"])
#: The wire structures as numpy dtypes, made once: numpy derives a dtype from a ctypes
#: buffer's format string, which costs more than the rest of a batch.
_TASK = np.dtype(_wire.WireTask)
_OUTCOME = np.dtype(_wire.WireOutcome)
#: Where a wire task's environment lies in its bytes.
_ENVIRONMENT = slice(
    _wire.WireTask.environment.offset,
    _wire.WireTask.environment.offset + _wire.WireTask.environment.size,
)


@dataclass(frozen=True)
class TaskBatch:
    """Tasks of one job shape, one row each: perform each with its ``thetas`` row in its
    ``contexts`` row (its ``seeds`` entry seeds anything random in it)."""

    ids: npt.NDArray[np.uint64]
    """Task ids, ``(n,)``."""
    jobs: npt.NDArray[np.uint32]
    """The job of each task, ``(n,)`` (the (method, run) of the run it belongs to)."""
    kinds: npt.NDArray[np.str_]
    """``"train"``, ``"evaluate"`` or ``"baseline"`` per task, ``(n,)``."""
    seeds: npt.NDArray[np.uint64]
    """The seed of everything random inside each rollout, ``(n,)``."""
    contexts: npt.NDArray[np.float64]
    """The contexts, ``(n, n_s)``, C-contiguous."""
    thetas: npt.NDArray[np.float64]
    """The parameters, ``(n, n_theta)``, C-contiguous."""

    def __len__(self) -> int:
        return len(self.ids)


#: What a batch rollout returns: arrays ``(rewards, scores)`` or ``(rewards, scores, ok)``, one
#: entry per task; a task whose ``ok`` is false, or whose reward or score is not finite, failed.
BatchResult = (
    tuple[npt.ArrayLike, npt.ArrayLike] | tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]
)
BatchRollout = Callable[[TaskBatch], BatchResult]


class TaskQueue:
    """Tasks received and not yet performed, in the order they came: whole answers as numpy
    views of their copied payloads, and how far into the first one the worker has got."""

    __slots__ = ("answers", "head", "size")

    def __init__(self) -> None:
        """An empty queue."""
        self.answers: deque[Any] = deque()
        self.head = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def extend(self, tasks: ctypes.Array[_wire.WireTask], served: Any) -> int | None:
        """Queue an answer's tasks (a private ctypes copy of its payload) if each is for the
        environment ``served`` (its wire bytes, from :func:`environment_bytes`); else the index
        of the first that is not."""
        rows = np.frombuffer(memoryview(tasks), dtype=_TASK)
        raw = rows.view(np.uint8).reshape(len(rows), -1)
        foreign = (raw[:, _ENVIRONMENT] != served).any(axis=1)
        if foreign.any():
            return int(np.argmax(foreign))
        self.answers.append(rows)
        self.size += len(rows)
        return None

    def take(self, most: int) -> Any:
        """Up to ``most`` tasks from the front that share the first one's context and theta
        lengths, as a structured array of wire tasks."""
        first = self.answers[0][self.head]
        shape = (first["context_len"], first["theta_len"])
        parts = []
        taken = 0
        while self.answers and taken < most:
            answer = self.answers[0]
            rows = answer[self.head : self.head + most - taken]
            same = (rows["context_len"] == shape[0]) & (rows["theta_len"] == shape[1])
            end = len(rows) if same.all() else int(np.argmin(same))
            parts.append(rows[:end])
            taken += end
            self.head += end
            if self.head == len(answer):
                self.answers.popleft()
                self.head = 0
            if end < len(rows):
                break
        self.size -= taken
        return parts[0] if len(parts) == 1 else np.concatenate(parts)


def environment_bytes(served: bytes) -> Any:
    """An environment's wire bytes as the array :meth:`TaskQueue.extend` compares tasks with."""
    return np.frombuffer(served, dtype=np.uint8)


def batch_of(rows: Any) -> TaskBatch:
    """The user's view of wire tasks ``rows`` that share their lengths."""
    n_context = min(int(rows["context_len"][0]), _wire.MAX_CONTEXT)
    n_theta = min(int(rows["theta_len"][0]), _wire.MAX_THETA)
    kinds = rows["kind"]
    return TaskBatch(
        ids=rows["task_id"].copy(),
        jobs=rows["job"].copy(),
        kinds=_KINDS[np.where(kinds < len(_KINDS), kinds, 0)],
        seeds=rows["seed"].copy(),
        contexts=np.ascontiguousarray(rows["context"][:, :n_context]),
        thetas=np.ascontiguousarray(rows["theta"][:, :n_theta]),
    )


def checked(result: Any, n: int) -> tuple[Any, Any, Any, str | None]:
    """``result`` of a batch rollout of ``n`` tasks as float rewards, float scores and the ok
    mask (non-finite numbers fail their task), with why the whole batch failed, if it did."""
    try:
        if len(result) not in (2, 3):
            raise TypeError(f"{len(result)} values")
        rewards = np.asarray(result[0], dtype=np.float64).reshape(-1)
        scores = np.asarray(result[1], dtype=np.float64).reshape(-1)
        ok = (
            np.ones(n, dtype=bool)
            if len(result) == 2
            else np.asarray(result[2], dtype=bool).reshape(-1)
        )
    except (TypeError, ValueError) as error:
        return (
            None,
            None,
            None,
            (
                f"it returned {type(result).__name__} ({error}); a batch rollout returns arrays "
                "(rewards, scores) or (rewards, scores, ok)"
            ),
        )
    if not len(rewards) == len(scores) == len(ok) == n:
        return (
            None,
            None,
            None,
            (
                f"it returned {len(rewards)} rewards, {len(scores)} scores and {len(ok)} ok flags "
                f"for {n} tasks"
            ),
        )
    return rewards, scores, ok & np.isfinite(rewards) & np.isfinite(scores), None


def write(outcomes: Any, rows: Any, rewards: Any, scores: Any, ok: Any) -> None:
    """Fill ``outcomes`` (a structured view of the request's next outcome slots) for the wire
    tasks ``rows``; a failed outcome carries zeros."""
    outcomes["job"] = rows["job"]
    outcomes["task_id"] = rows["task_id"]
    outcomes["ok"] = ok
    if rewards is None:
        outcomes["reward"] = 0.0
        outcomes["score"] = 0.0
    else:
        outcomes["reward"] = np.where(ok, rewards, 0.0)
        outcomes["score"] = np.where(ok, scores, 0.0)
    outcomes["diagnostics_len"] = 0


def outcome_view(outcomes: ctypes.Array[_wire.WireOutcome]) -> Any:
    """A structured numpy view of a message's outcome array (writes reach the message)."""
    return np.frombuffer(memoryview(outcomes), dtype=_OUTCOME)
