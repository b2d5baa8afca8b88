"""The iceoryx2 plumbing of a worker, mirroring ``shared/wire/src/ipc.rs``: the run's config
(prefix, creation timeout, a worker node that leaves cleaning up dead nodes to the learner),
the services opened with the run's limits, liveness of processes, and removal of a run's files
once its last node is gone."""

from __future__ import annotations

import logging
import os
import re
import stat
import time
from pathlib import Path
from typing import Any

import iceoryx2 as iox2

from . import _wire
from .errors import AcpsWorkerError

log = logging.getLogger("acps_worker")
_RUN_NAME = re.compile(r"[A-Za-z0-9-]{1,40}")
_WORKER_NAME = re.compile(r"[A-Za-z0-9._-]{1,128}")
#: What a worker's name may be (``ipc::WORKER_NAMES``).
WORKER_NAMES = (
    "1 to 128 characters of ASCII letters, digits, '-', '_' and '.', "
    f"other than '{_wire.LEARNER_NODE}' (the learner's node)"
)
#: iceoryx2's reasons for failing to open a service, in words (``ipc::OpenFailure``), by the
#: part of the reason's name that tells them apart.
_OPEN_FAILURES = (
    (("HangsInCreation",), "a process of this run died while creating it"),
    (
        ("DoesNotExist", "CorruptedState"),
        (
            "it was removed while this process opened it, or has files missing: a process of "
            "this run died while creating it, or the run was ending"
        ),
    ),
    (
        ("InFlux", "MarkedForDestruction", "BeingCreatedByAnotherInstance"),
        "other processes of this run were creating or removing it at the same moment",
    ),
    (("ExceedsMaxNumberOfNodes",), "it already serves the most processes a run has"),
    (("InsufficientPermissions",), "another user's process created it"),
    (
        ("Incompatible", "DoesNotSupport", "VersionMismatch"),
        "a process of another acps build created it with other types or settings",
    ),
)
#: Attempts at listing a run's nodes (a listing fails while any node is created or removed).
LIST_ATTEMPTS = 50


def check_run_name(run: str) -> str:
    """``run`` if it is a valid run name (1 to 40 letters, digits and '-'), else ValueError."""
    if not _RUN_NAME.fullmatch(run):
        raise ValueError(f"run name '{run}' must be 1 to 40 characters of letters, digits and '-'")
    return run


class SecretFileError(AcpsWorkerError):
    """The run's secret file is not one this user's learner wrote, or ``ACPS_RUN_SECRET``
    holds no secret."""


def _secret_from_hex(text: str) -> bytes | None:
    """The secret written in ``text`` as the learner writes it, else None."""
    text = text.strip()
    if len(text) != 2 * _wire.SECRET_BYTES or not re.fullmatch(r"[0-9a-fA-F]+", text):
        return None
    return bytes.fromhex(text)


def find_secret(run: str) -> tuple[bytes | None, str]:
    """The secret a worker joining ``run`` sends, and where it found it, in the words of the
    Rust worker's ``SecretOrigin``: ``ACPS_RUN_SECRET`` when ``ACPS_RUN`` names ``run`` (a worker
    the fleet started), else the run's secret file, else none."""
    text = os.environ.get(_wire.SECRET_ENV)
    if os.environ.get(_wire.RUN_ENV) == run and text is not None:
        secret = _secret_from_hex(text)
        if secret is None:
            raise SecretFileError(
                f"{_wire.SECRET_ENV}: must be {2 * _wire.SECRET_BYTES} hexadecimal digits (the "
                "run's secret, set by the fleet that starts the worker), "
                f"got {len(text)} characters"
            )
        return secret, f"this worker sent the secret in {_wire.SECRET_ENV}"
    path = Path(_wire.SECRET_FILE.format(run=run))

    def refuse(reason: str) -> SecretFileError:
        return SecretFileError(f"reading run '{run}''s secret from {path}: {reason}")

    try:
        status = path.lstat()
    except FileNotFoundError:
        return None, (
            f"this worker found no secret ({_wire.SECRET_ENV} is not set for this run and "
            f"{path} does not exist)"
        )
    except OSError as error:
        raise refuse(str(error)) from error
    # Checked before it is opened: opening a FIFO would block, and a secret another user could
    # have written, or can read, is none.
    if not stat.S_ISREG(status.st_mode):
        raise refuse("not a regular file")
    if status.st_uid != os.geteuid():
        raise refuse(f"it belongs to user {status.st_uid}, not this process's user {os.geteuid()}")
    if status.st_mode & 0o077:
        raise refuse(
            f"its mode is {status.st_mode & 0o777:o}: other users may read or change it "
            "(acps writes 600)"
        )
    try:
        with path.open("rb") as file:
            content = file.read(64)
    except FileNotFoundError:
        return None, f"this worker found no secret ({path} was removed as it was read)"
    except OSError as error:
        raise refuse(str(error)) from error
    secret = _secret_from_hex(content.decode("utf-8", "replace"))
    if secret is None:
        raise refuse(
            f"it holds {len(content)} bytes, not {2 * _wire.SECRET_BYTES} hexadecimal digits"
        )
    return secret, f"this worker sent the secret in {path}"


def prefix(run: str) -> str:
    """The iceoryx2 file prefix of ``run``'s resources."""
    return _wire.PREFIX_FORMAT.format(run=run)


def iceoryx2_root() -> Path:
    """This user's directory of iceoryx2's node and service files (``ipc::iceoryx2_root``):
    iceoryx2's default, /tmp/iceoryx2, only its first user may write in."""
    return Path(_wire.ROOT_FORMAT.format(uid=os.geteuid()))


class RootError(AcpsWorkerError):
    """This user's directory of iceoryx2's files cannot be made, or is not theirs alone; or the
    run is another user's."""


def own_root(run: str) -> None:
    """Make :func:`iceoryx2_root` if it is missing, accessible to its owner only, or refuse
    one that is not a directory of this user's (``ipc::own_root``)."""
    root = iceoryx2_root()

    def refuse(reason: str) -> RootError:
        return RootError(f"iceoryx2's directory {root} for run '{run}': {reason}")

    try:
        root.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError as error:
        raise refuse(str(error)) from error
    try:
        status = root.lstat()
        if not stat.S_ISDIR(status.st_mode):
            raise refuse("it is not a directory; remove it")
        if status.st_uid != os.geteuid():
            raise refuse(
                f"it belongs to user {status.st_uid}, not to this process's user "
                f"{os.geteuid()}; remove it"
            )
        if status.st_mode & 0o077:
            root.chmod(0o700)
    except OSError as error:
        raise refuse(str(error)) from error


def check_owner(run: str, node: str) -> None:
    """Refuse ``run`` when its files in /dev/shm are another user's (``ipc::node_with``): that
    user's learner keeps its nodes where this process would never find them."""
    start, user = prefix(run), os.geteuid()
    for path in Path("/dev/shm").glob(start + "*"):
        try:
            owner = path.lstat().st_uid
        except OSError:
            continue
        if owner != user:
            raise RootError(
                f"creating node '{node}' of run '{run}': the run's shared memory belongs to "
                f"user {owner}, who alone may use it; run this process as that user (this one "
                f"runs as user {user})"
            )


def run_config(run: str, worker: bool = True) -> Any:
    """The iceoryx2 config of ``run``, in this user's :func:`iceoryx2_root`; a worker's leaves
    cleaning up dead nodes to the learner (``ipc::worker_node``: each look reads every node's
    files of the run)."""
    config = iox2.config.default()
    config.global_cfg.prefix = iox2.FileName.new(prefix(run))
    config.global_cfg.root_path = iox2.Path.new(str(iceoryx2_root()) + "/")
    config.global_cfg.creation_timeout = iox2.Duration.from_millis(_wire.CREATION_TIMEOUT_MS)
    if worker:
        config.global_cfg.node.cleanup_dead_nodes_on_creation = False
        config.global_cfg.node.cleanup_dead_nodes_on_destruction = False
        config.global_cfg.service.cleanup_dead_nodes_on_open = False
    return config


def check_worker_name(name: str) -> str:
    """``name`` if a worker may take it, else ValueError saying what names may be."""
    if not (_WORKER_NAME.fullmatch(name) and name != _wire.LEARNER_NODE):
        shown = f"{len(name)} characters" if len(name) > 128 else repr(name)
        raise ValueError(f"a worker's name must be {WORKER_NAMES}, got {shown}")
    return name


def open_error(what: str, error: BaseException) -> AcpsWorkerError:
    """An error for opening the service ``what``, with iceoryx2's reason in words."""
    reason = str(error)
    for parts, words in _OPEN_FAILURES:
        if any(part in reason for part in parts):
            return AcpsWorkerError(f"{what}: {words} ({reason})")
    return ipc_error(what, error)


def ipc_error(what: str, error: BaseException) -> AcpsWorkerError:
    """An error for ``what`` with iceoryx2's reason."""
    return AcpsWorkerError(f"{what}: {type(error).__name__}: {error}")


def list_nodes(config: Any) -> list[Any]:
    """The node states of the run of ``config``, retried while the listing fails."""
    for attempt in range(LIST_ATTEMPTS):
        try:
            return list(iox2.Node.list(iox2.ServiceType.Ipc, config))
        except iox2.NodeListFailure as error:
            if attempt == LIST_ATTEMPTS - 1:
                raise ipc_error("listing the run's nodes", error) from error
            time.sleep(0.001)
    raise AssertionError("unreachable")


def process_runs(pid: int) -> bool:
    """Whether process ``pid`` runs: it exists and is no zombie."""
    try:
        with open(f"/proc/{pid}/stat", encoding="utf-8", errors="replace") as stat:
            text = stat.read()
    except OSError:
        return False
    _, _, rest = text.rpartition(")")
    return not rest.lstrip().startswith(("Z", "X"))


def alive_learner_pid(config: Any) -> int | None:
    """The PID of the run's live learner node, ``None`` when no learner node lives."""
    for state in list_nodes(config):
        if isinstance(state, iox2.NodeState.Alive):
            details = state[0].details
            if details is not None and details.name.as_str() == _wire.LEARNER_NODE:
                return int(details.process_id)
    return None


def run_files(run: str) -> list[Path]:
    """Files of ``run`` in /dev/shm and this user's :func:`iceoryx2_root` (recursively)."""
    start = prefix(run)
    found: list[Path] = []
    stack = [Path("/dev/shm"), iceoryx2_root()]
    while stack:
        directory = stack.pop()
        try:
            entries = list(os.scandir(directory))
        except OSError:
            continue
        for entry in entries:
            if entry.name.startswith(start):
                found.append(Path(entry.path))
            elif entry.is_dir(follow_symlinks=False):
                stack.append(Path(entry.path))
    return found


def remove_run_files_if_last(run: str) -> int:
    """After this process's node is gone: when no node of ``run`` lives, clean up dead nodes and
    remove the files iceoryx2 keeps on purpose (``ipc::remove_run_files``); returns how many
    files went. Best effort: a run with a live node is left alone."""
    config = run_config(run, worker=False)
    try:
        states = list_nodes(config)
    except AcpsWorkerError:
        return 0
    alive = 0
    for state in states:
        if isinstance(state, iox2.NodeState.Dead):
            try:
                state[0].try_remove_stale_resources()
            except Exception as error:  # noqa: BLE001 - best effort, as the Rust side
                log.debug("cleaning up a dead node of run '%s' failed: %s", run, error)
        elif not isinstance(state, iox2.NodeState.Inaccessible):
            alive += 1
    if alive > 0:
        return 0
    removed = 0
    nodes = iceoryx2_root() / "nodes"
    for path in run_files(run):
        try:
            if path.is_dir():
                for child in sorted(path.rglob("*"), reverse=True):
                    child.rmdir() if child.is_dir() else child.unlink()
                path.rmdir()
            else:
                path.unlink()
            removed += 1
        except OSError:
            continue
        parent = path.parent
        if parent.parent == nodes:
            try:
                parent.rmdir()
            except OSError:
                pass
    return removed
