"""Type stubs of the extension module ``acps._native`` (python/src)."""

from collections.abc import Callable
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

#: ``perform(ids, kinds, seeds, contexts, thetas) -> (rewards, scores, ok)`` of :func:`run`.
Perform: TypeAlias = Callable[
    [
        npt.NDArray[np.uint64],
        npt.NDArray[np.uint32],
        npt.NDArray[np.uint64],
        npt.NDArray[np.float64],
        npt.NDArray[np.float64],
    ],
    tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]],
]

__version__: str

class AcpsError(Exception):
    """Every error acps raises."""

class SettingsError(AcpsError):
    """Settings acps refuses: the message names the key, where it stands and its range."""

class TellError(AcpsError):
    """Outcomes the learner cannot take; nothing of the batch was taken."""

class CheckpointError(AcpsError):
    """A checkpoint that cannot be written, read or applied."""

def cli(argv: list[str], program: list[str]) -> int:
    """Run the acps command line ``argv``; ``program`` is how it starts itself again."""

def run(
    path: str | None,
    json: str | None,
    origin: str,
    out: str | None,
    perform: Perform | None,
    quiet: bool,
    checkpoint_every: int,
    resume: bool,
    force: bool,
    progress: Callable[[str, int, int, str, bool], None] | None,
    line: bool,
) -> str:
    """Run a whole experiment into its run directory; returns the directory."""

class NativeLearner:
    """A learner of one (method, run) of an experiment."""

    @staticmethod
    def from_path(path: str, method: str | None, run: int) -> NativeLearner: ...
    @staticmethod
    def from_json(json: str, origin: str, method: str | None, run: int) -> NativeLearner: ...
    def ask(
        self, n: int
    ) -> tuple[
        npt.NDArray[np.uint64],
        npt.NDArray[np.uint32],
        npt.NDArray[np.uint64],
        npt.NDArray[np.float64],
        npt.NDArray[np.float64],
    ]: ...
    def tell(
        self,
        ids: npt.NDArray[np.uint64],
        rewards: npt.NDArray[np.float64],
        scores: npt.NDArray[np.float64],
        ok: npt.NDArray[np.bool_] | None = None,
    ) -> None: ...
    @property
    def done(self) -> bool: ...
    @property
    def episodes(self) -> tuple[int, int]: ...
    @property
    def tasks_in_flight(self) -> int: ...
    @property
    def evaluations(self) -> list[tuple[int, float | None, int]]: ...
    @property
    def identity(self) -> tuple[str, str, int, int]: ...
    @property
    def sizes(self) -> tuple[int, int, int]: ...
    def contexts(self, test: bool) -> npt.NDArray[np.float64]: ...
    def mean(self, contexts: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
    def covariance(self) -> npt.NDArray[np.float64]: ...
    def save(self, path: str) -> None: ...
    def restore(self, path: str) -> None: ...
