"""serve() against a real learner: `acps run function --workers 0 --run NAME` (the built-in
contextual function; the environment identity its run 0 needs is read from a policy file the
Rust build writes)."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import stat
import subprocess
import sys
import tempfile
import threading
import unittest
from pathlib import Path
from unittest import mock

import acps_worker
from acps_worker import Environment, Exit, NoLearnerError, Policy, RefusedError, Task, _ipc, _wire

from .support import WATCHDOG, Learner, Serving, acps, leftovers, run_name, wait_for

#: A short run of one method: 200 training episodes and the evaluations between them.
FUNCTION = ["function", "--runs", "1", "--episodes", "200", "--method", "random"]


def bowl(task: Task) -> tuple[float, float]:
    """A cheap deterministic rollout with a finite score (the function's metric takes its log)."""
    total = sum((t - task.context[i % len(task.context)]) ** 2 for i, t in enumerate(task.theta))
    return -total, 1.0 + math.sqrt(total)


class ServeTest(unittest.TestCase):
    """Joining, finishing, failing rollouts, refusals, stopping, a vanished learner, cleanup."""

    environment: Environment

    @classmethod
    def setUpClass(cls) -> None:
        """The identity of the function problem's run 0, from a policy file of the Rust build."""
        with tempfile.TemporaryDirectory() as out:
            acps("experiment", "function", "--runs", "1", "--episodes", "10", "--out", out, "-q")
            environment = Policy.load(out).environment
        assert environment is not None
        cls.environment = environment

    def assert_clean(self, run: str) -> None:
        """Nothing of ``run`` is left in /dev/shm or this user's iceoryx2 directory."""
        self.assertEqual(leftovers(run), [], f"files of run {run} left behind")

    def test_a_worker_serves_a_run_to_its_end(self) -> None:
        """Every task is performed; the learner finishes; nothing is left behind."""
        run = run_name("finish")
        learner = Learner(run, FUNCTION)
        report = acps_worker.serve(bowl, run, environment=self.environment, queue_depth=8)
        summary = learner.finished()
        self.assertEqual(report.exit, Exit.FINISHED)
        self.assertEqual(report.failed, 0)
        self.assertGreaterEqual(report.rollouts, 200, "every training episode, and evaluations")
        self.assertEqual(summary["training_episodes"], 200)
        self.assert_clean(run)

    def test_failed_rollouts_are_failed_outcomes_not_crashes(self) -> None:
        """None, exceptions, non-finite numbers and malformed results count as failed; the
        first is logged with its traceback; the run still finishes."""
        run = run_name("failing")
        learner = Learner(run, FUNCTION)
        calls = [0]

        def flaky(task: Task) -> tuple[float, float] | None:
            calls[0] += 1
            match calls[0] % 10:
                case 1:
                    raise RuntimeError("simulator exploded")
                case 2:
                    return None
                case 3:
                    return (math.nan, 1.0)
                case 4:
                    return "bad"  # type: ignore[return-value]
            return bowl(task)

        with self.assertLogs("acps_worker", "ERROR") as logs:
            report = acps_worker.serve(flaky, run, environment=self.environment)
        learner.finished()
        self.assertEqual(report.exit, Exit.FINISHED)
        self.assertEqual(report.rollouts, calls[0])
        self.assertEqual(
            report.failed, sum(1 for i in range(1, calls[0] + 1) if i % 10 in (1, 2, 3, 4))
        )
        errors = [r for r in logs.records if r.levelname == "ERROR"]
        self.assertEqual(len(errors), 1, "only the first failure is logged")
        self.assertIn("simulator exploded", logs.output[0])
        self.assertIn("Traceback (most recent call last)", logs.output[0], "with its traceback")
        self.assert_clean(run)

    def test_too_many_diagnostics_is_a_clear_error(self) -> None:
        """17 diagnostics cannot cross the wire: the worker stops saying so."""
        run = run_name("diagnostics")
        learner = Learner(run, FUNCTION)
        try:
            with self.assertRaisesRegex(acps_worker.ProtocolError, "17 values.*at most 16"):
                acps_worker.serve(
                    lambda task: (0.0, 1.0, [0.0] * 17), run, environment=self.environment
                )
            report = acps_worker.serve(
                lambda task: (*bowl(task), [1.0] * 16), run, environment=self.environment
            )
            self.assertEqual((report.exit, report.failed), (Exit.FINISHED, 0))
        finally:
            learner.finished()
        self.assert_clean(run)

    def test_refusals_name_both_sides(self) -> None:
        """Another environment identity and another protocol version are refused, and the
        learner says why too."""
        run = run_name("refused")
        learner = Learner(run, FUNCTION)
        try:
            other = Environment("contextual-function", "something else", (2, 20, 0))
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl, run, environment=other)
            # The learner's settings text (the function's matrix) is longer than a message
            # carries: its start and its length.
            self.assertRegex(
                refused.exception.reason,
                rf'^this worker serves {re.escape(str(other))} = "something else"; the run\'s '
                rf'jobs need {re.escape(str(self.environment))} = "\[0\.[0-9., ]+"\.\.\. '
                r"\([0-9]+ bytes\)$",
            )
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl, run, environment=self.environment, _protocol=6)
            self.assertEqual(
                refused.exception.reason,
                f"protocol version 6 here, {_wire.PROTOCOL_VERSION} at the learner (another build)",
            )
            with self.assertRaises(RefusedError) as refused:
                acps_worker.serve(bowl, run)
            self.assertIn("this worker serves no named environment", refused.exception.reason)
            # A secret that is not the run's, as a worker of an earlier run of the name has.
            saved = {key: os.environ.get(key) for key in (_wire.RUN_ENV, _wire.SECRET_ENV)}
            os.environ.update({_wire.RUN_ENV: run, _wire.SECRET_ENV: "0f" * _wire.SECRET_BYTES})
            try:
                with self.assertRaises(RefusedError) as refused:
                    acps_worker.serve(bowl, run, environment=self.environment)
            finally:
                for key, value in saved.items():
                    if value is None:
                        os.environ.pop(key, None)
                    else:
                        os.environ[key] = value
            self.assertEqual(
                refused.exception.reason,
                "its messages do not carry the run's secret: this worker sent the secret in "
                f"{_wire.SECRET_ENV}; a worker started by hand reads the file the learner "
                f"writes, or takes the secret in {_wire.SECRET_ENV}",
            )
            acps_worker.serve(bowl, run, environment=self.environment)
        finally:
            learner.finished()
        log = learner.output()
        self.assertIn("do not carry the run's secret", log)
        self.assertIn(f"protocol 6 (ours {_wire.PROTOCOL_VERSION})", log)
        self.assertIn(f"it serves environment {other}", log)
        self.assert_clean(run)

    def test_the_secret_comes_from_the_environment_or_the_learners_file(self) -> None:
        """ACPS_RUN_SECRET counts for the run ACPS_RUN names only; the file must be this
        user's alone and hold a secret; every refusal names the file or the variable."""
        run = run_name("secret")
        path = _wire.SECRET_FILE.format(run=run)
        secret = bytes(range(_wire.SECRET_BYTES))
        saved = {key: os.environ.pop(key, None) for key in (_wire.RUN_ENV, _wire.SECRET_ENV)}
        try:
            missing = (
                f"this worker found no secret ({_wire.SECRET_ENV} is not set for this run "
                f"and {path} does not exist)"
            )
            self.assertEqual(_ipc.find_secret(run), (None, missing))
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w") as file:
                file.write(secret.hex() + "\n")
            self.assertEqual(
                _ipc.find_secret(run), (secret, f"this worker sent the secret in {path}")
            )
            # Another run's variable does not count; this run's does, and must be a secret.
            os.environ.update({_wire.RUN_ENV: "another", _wire.SECRET_ENV: "ab" * 16})
            self.assertEqual(_ipc.find_secret(run)[0], secret)
            os.environ[_wire.RUN_ENV] = run
            self.assertEqual(_ipc.find_secret(run)[0], bytes([0xAB] * 16))
            os.environ[_wire.SECRET_ENV] = "xyz"
            with self.assertRaisesRegex(
                _ipc.SecretFileError, "ACPS_RUN_SECRET: must be 32 hexadecimal digits.*got 3"
            ):
                _ipc.find_secret(run)
            del os.environ[_wire.SECRET_ENV]
            os.chmod(path, 0o644)
            with self.assertRaisesRegex(_ipc.SecretFileError, f"{path}: its mode is 644"):
                _ipc.find_secret(run)
            os.chmod(path, 0o600)
            with open(path, "w") as file:
                file.write("short")
            with self.assertRaisesRegex(_ipc.SecretFileError, "holds 5 bytes, not 32"):
                _ipc.find_secret(run)
        finally:
            if os.path.exists(path):
                os.remove(path)
            for key, value in saved.items():
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value

    def test_the_iceoryx2_directory_is_this_users_alone(self) -> None:
        """own_root makes the directory 0700, narrows a wider one and refuses a file or another
        user's directory; check_owner refuses a run whose shared memory is another user's."""
        run = run_name("root")
        with tempfile.TemporaryDirectory() as d:
            root = Path(d) / "root"
            with mock.patch.object(_ipc, "iceoryx2_root", return_value=root):
                _ipc.own_root(run)
                self.assertEqual(stat.S_IMODE(root.stat().st_mode), 0o700)
                root.chmod(0o755)
                _ipc.own_root(run)
                self.assertEqual(stat.S_IMODE(root.stat().st_mode), 0o700)
                root.rmdir()
                root.write_text("")
                with self.assertRaisesRegex(
                    _ipc.RootError, f"{root} for run '{run}': it is not a directory; remove it"
                ):
                    _ipc.own_root(run)
                root.unlink()
                if os.geteuid() == 0:
                    root.mkdir(mode=0o700)
                    os.chown(root, 65534, 65534)
                    with self.assertRaisesRegex(
                        _ipc.RootError, "it belongs to user 65534, not to this process's user 0"
                    ):
                        _ipc.own_root(run)
        if os.geteuid() != 0:
            return
        # Root can forge what another user's learner leaves in /dev/shm.
        forged = Path("/dev/shm") / (_ipc.prefix(run) + "forged")
        forged.write_bytes(b"")
        os.chown(forged, 65534, 65534)
        try:
            with self.assertRaisesRegex(
                _ipc.RootError,
                f"creating node 'w' of run '{run}': the run's shared memory belongs to user "
                "65534, who alone may use it",
            ):
                _ipc.check_owner(run, "w")
        finally:
            forged.unlink()

    def test_no_learner_is_an_error_and_leaves_nothing(self) -> None:
        """A worker whose learner never comes gives up and removes what it created."""
        run = run_name("nolearner")
        with self.assertRaisesRegex(NoLearnerError, f"no learner serves run '{run}'"):
            acps_worker.serve(bowl, run, startup_timeout=0.2)
        self.assert_clean(run)

    def test_options_are_checked(self) -> None:
        """queue_depth out of range, a bad run name, no run at all."""
        with self.assertRaisesRegex(ValueError, "queue_depth must be in 1..=128, got 0"):
            acps_worker.serve(bowl, "x", queue_depth=0)
        # The old name still works, with a warning that names the new one.
        with (
            self.assertWarnsRegex(DeprecationWarning, "use queue_depth"),
            self.assertRaisesRegex(ValueError, "in_flight must be in 1..=128, got 129"),
        ):
            acps_worker.serve(bowl, "x", in_flight=129)
        with self.assertRaisesRegex(ValueError, "must be 1 to 40 characters"):
            acps_worker.serve(bowl, "a_b")
        # Worker names as the Rust worker takes them.
        for name, shown in [
            ("", "''"),
            ("a/b", "'a/b'"),
            ("learner", "'learner'"),
            ("w" * 129, "129 characters"),
        ]:
            with (
                self.subTest(name=name[:10]),
                self.assertRaisesRegex(
                    ValueError,
                    f"name must be 1 to 128 characters of ASCII .*, got {re.escape(shown)}$",
                ),
            ):
                acps_worker.serve(bowl, "x", name=name)
        environ = dict(os.environ)
        os.environ.pop("ACPS_RUN", None)
        try:
            with self.assertRaisesRegex(ValueError, "ACPS_RUN"):
                acps_worker.serve(bowl)
        finally:
            os.environ.update(environ)

    def test_stop_flag_ends_the_worker_and_another_finishes_the_run(self) -> None:
        """A stopped worker reports so; the learner hands its tasks to the next worker."""
        run = run_name("stop")
        learner = Learner(run, FUNCTION)
        stop = threading.Event()

        def stopping(task: Task) -> tuple[float, float]:
            stop.set()
            return bowl(task)

        first = acps_worker.serve(stopping, run, environment=self.environment, stop=stop)
        self.assertEqual((first.exit, first.rollouts), (Exit.STOPPED, 1))
        second = acps_worker.serve(bowl, run, environment=self.environment)
        self.assertEqual(second.exit, Exit.FINISHED)
        learner.finished()
        self.assert_clean(run)

    def test_a_killed_learner_is_noticed(self) -> None:
        """SIGKILL of the learner mid-run: the worker returns learner-gone within seconds and
        leaves nothing behind (it is the run's last node)."""
        run = run_name("gone")
        learner = Learner(
            run, ["function", "--runs", "1", "--episodes", "1000000", "--method", "random"]
        )
        busy = threading.Event()
        count = [0]

        def counting(task: Task) -> tuple[float, float]:
            count[0] += 1
            if count[0] >= 100:
                busy.set()
            return bowl(task)

        worker = Serving(rollout=counting, run=run, environment=self.environment)
        wait_for(busy.is_set, "100 rollouts")
        learner.kill()
        report = worker.join()
        self.assertEqual(report.exit, Exit.LEARNER_GONE)
        self.assert_clean(run)

    def test_sigterm_ends_a_worker_process_cleanly(self) -> None:
        """A worker process told to terminate reports 'stopped' and exits 0; the run goes on
        and ends with another worker; nothing is left."""
        run = run_name("sigterm")
        learner = Learner(run, FUNCTION)
        script = (
            "import json, sys, math, acps_worker\n"
            f"env = acps_worker.Environment('{self.environment.name}', "
            f"{self.environment.settings}, {self.environment.parameters})\n"
            "def rollout(task):\n"
            "    print('rollout', flush=True)\n"
            "    return -sum(t * t for t in task.theta), 1.0\n"
            f"report = acps_worker.serve(rollout, '{run}', environment=env)\n"
            "print(json.dumps({'exit': report.exit.value, 'rollouts': report.rollouts}))\n"
        )
        worker = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
        try:
            assert worker.stdout is not None
            self.assertEqual(worker.stdout.readline().strip(), "rollout")
            worker.send_signal(signal.SIGTERM)
            out, _ = worker.communicate(timeout=WATCHDOG)
        finally:
            if worker.poll() is None:
                worker.kill()
        self.assertEqual(worker.returncode, 0)
        report = json.loads(out.strip().splitlines()[-1])
        self.assertEqual(report["exit"], "stopped")
        acps_worker.serve(bowl, run, environment=self.environment)
        learner.finished()
        self.assert_clean(run)


if __name__ == "__main__":
    unittest.main()
