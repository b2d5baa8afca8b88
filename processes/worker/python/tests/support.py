"""Helpers of the tests: the acps binary, learners under a watchdog, waiting for conditions."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import threading
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

import acps_worker
from acps_worker import _ipc

#: The worktree's root (this file is processes/worker/python/tests/support.py).
ROOT = Path(__file__).resolve().parents[4]
#: How long any awaited condition may take before the test fails.
WATCHDOG = 120.0


def acps_bin() -> str:
    """The acps binary: $ACPS_BIN, else the worktree's release build."""
    path = os.environ.get("ACPS_BIN", str(ROOT / "target" / "release" / "acps"))
    if not Path(path).is_file():
        raise FileNotFoundError(f"no acps binary at {path}: build it or set ACPS_BIN")
    return path


def acps(*args: str) -> str:
    """Run ``acps args`` under a watchdog; its stdout, or AssertionError with its output."""
    done = subprocess.run(
        ["timeout", "--signal=KILL", str(int(WATCHDOG)), acps_bin(), *args],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise AssertionError(
            f"acps {' '.join(args)} exited with {done.returncode}\n"
            f"stdout: {done.stdout}\nstderr: {done.stderr}"
        )
    return done.stdout


def run_name(test: str) -> str:
    """A run name unique to this process and test."""
    return f"py{os.getpid()}-{test}"[:40]


def wait_for(condition: Callable[[], bool], what: str, timeout: float = WATCHDOG) -> None:
    """Poll ``condition`` until it holds; AssertionError naming ``what`` after ``timeout``."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout}s waiting for {what}")
        time.sleep(0.01)


class Learner:
    """``acps run ... --workers 0 --run NAME`` in the background, under a watchdog."""

    def __init__(self, run: str, args: list[str]) -> None:
        """Start the learner of ``run`` with the experiment arguments ``args``."""
        self.run = run
        self.dir = Path(tempfile.mkdtemp(prefix=f"acps-{run}-"))
        # Removed once the learner object is gone, at the latest when the tests end.
        weakref.finalize(self, shutil.rmtree, self.dir, True)
        self.out = self.dir / "out"
        self.log = self.dir / "learner.log"
        with open(self.log, "w") as log:
            self.process = subprocess.Popen(
                [
                    "timeout",
                    "--signal=KILL",
                    str(int(WATCHDOG)),
                    acps_bin(),
                    "run",
                    *args,
                    "--workers",
                    "0",
                    "--run",
                    run,
                    "--out",
                    str(self.out),
                    "-q",
                ],
                stdout=log,
                stderr=subprocess.STDOUT,
            )

    def output(self) -> str:
        """What the learner printed so far."""
        return self.log.read_text(errors="replace")

    def wait(self) -> int:
        """Wait for the learner to exit (the watchdog ends it at worst); its exit code."""
        return self.process.wait(timeout=WATCHDOG + 10)

    def finished(self) -> dict[str, Any]:
        """The summary of a learner that exited with success, else AssertionError."""
        code = self.wait()
        if code != 0:
            raise AssertionError(f"learner exited with {code}:\n{self.output()}")
        return json.loads((self.out / "summary.json").read_text())  # type: ignore[no-any-return]

    def kill(self) -> None:
        """SIGKILL the learner (the acps process, not its watchdog)."""
        children = Path(f"/proc/{self.process.pid}/task/{self.process.pid}/children")
        pids = children.read_text().split() if children.exists() else []
        for pid in pids:
            os.kill(int(pid), 9)
        self.process.wait(timeout=WATCHDOG)


class Serving:
    """serve() on a thread, with its result or exception."""

    def __init__(self, **kwargs: Any) -> None:
        """Start ``acps_worker.serve(**kwargs)``."""
        self.result: acps_worker.Report | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._serve, kwargs=kwargs, daemon=True)
        self.thread.start()

    def _serve(self, **kwargs: Any) -> None:
        try:
            self.result = acps_worker.serve(**kwargs)
        except BaseException as error:  # noqa: BLE001 - handed to the test
            self.error = error

    def join(self) -> acps_worker.Report:
        """The worker's report, or its exception raised here."""
        self.thread.join(WATCHDOG)
        if self.thread.is_alive():
            raise AssertionError(f"the worker did not end within {WATCHDOG}s")
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result


def leftovers(run: str) -> list[Path]:
    """Files of ``run`` left in /dev/shm and this user's iceoryx2 directory."""
    return _ipc.run_files(run)
