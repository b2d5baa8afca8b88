"""The exceptions of a worker that cannot serve."""

from __future__ import annotations


class AcpsWorkerError(Exception):
    """A worker could not serve (the base of every acps_worker error)."""


class NoLearnerError(AcpsWorkerError):
    """No learner served the run within the startup timeout."""

    def __init__(self, run: str, waited: float) -> None:
        """No learner of ``run`` came within ``waited`` seconds."""
        super().__init__(f"no learner serves run '{run}' (waited {waited:.3f}s)")
        self.run = run
        self.waited = waited


class RefusedError(AcpsWorkerError):
    """The learner refused this worker; ``reason`` names both sides' protocol versions, run
    identities or environments."""

    def __init__(self, run: str, reason: str) -> None:
        """The learner of ``run`` refused this worker for ``reason``."""
        super().__init__(f"the learner of run '{run}' refused this worker: {reason}")
        self.run = run
        self.reason = reason


class ProtocolError(AcpsWorkerError):
    """The learner sent what this worker cannot take (a task of another environment, an answer
    of unknown meaning), or an outcome does not fit the wire."""
