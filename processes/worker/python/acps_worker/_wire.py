"""The ctypes mirror of the Rust wire payloads (`shared/wire/src/wire.rs`) and of the limits,
codes and service settings of `shared/wire/src/ipc.rs`.

Every structure declares its fields in Rust's order with Rust's element types, and gives
iceoryx2 the Rust type name through a ``type_name()`` static method: iceoryx2 matches payload
types by name, size and alignment. ``tests/test_layout.py`` checks all of it against the JSON
that ``acps protocol`` prints.
"""

from __future__ import annotations

import ctypes

#: Version of the wire format (Rust: ``PROTOCOL_VERSION``).
PROTOCOL_VERSION = 10
#: Most bytes of an environment's name.
MAX_NAME = 32
#: Largest context a task carries.
MAX_CONTEXT = 8
#: Largest parameter vector a task carries.
MAX_THETA = 64
#: Largest diagnostics vector an outcome carries.
MAX_DIAGNOSTICS = 16
#: Most tasks one answer carries, and most outcomes one request carries.
MAX_BATCH = 64
#: Most bytes of a settings text a request or a refusal carries.
MAX_SETTINGS_TEXT = 256
#: Most workers one run serves.
MAX_WORKERS = 128
#: Most tasks one worker keeps in flight.
MAX_IN_FLIGHT_PER_WORKER = 128
#: A worker's queue unless set: the tasks it keeps asked for or queued (as Rust's).
DEFAULT_QUEUE_DEPTH = 4
#: Most requests one worker has waiting for tasks; one more may only deliver outcomes.
MAX_ASKING_REQUESTS = 8

#: Task kinds by wire code.
KINDS = {"train": 0, "evaluate": 1, "baseline": 2}
#: Answer codes.
RESPONSE_TASK = 1
RESPONSE_STOP = 2
RESPONSE_REFUSED = 3
#: Refusal codes.
REFUSAL_PROTOCOL = 1
REFUSAL_RUN = 2
REFUSAL_ENVIRONMENT = 3
REFUSAL_SIZES = 4
REFUSAL_SECRET = 5
#: Bytes of a run's secret.
SECRET_BYTES = 16

#: The environment variable naming the run a started worker joins.
RUN_ENV = "ACPS_RUN"
#: The environment variable giving a started worker its run's secret (hexadecimal).
SECRET_ENV = "ACPS_RUN_SECRET"
#: Where the learner writes its run's secret for workers started by hand.
SECRET_FILE = "/dev/shm/acps_{run}_secret"
#: What the iceoryx2 prefix of a run's files is made from.
PREFIX_FORMAT = "acps_{run}_"
#: Each user's directory of iceoryx2's node and service files.
ROOT_FORMAT = "/tmp/acps-iceoryx2-{uid}/"
#: How long a process waits for another to finish creating a service of the run.
CREATION_TIMEOUT_MS = 10_000
#: Most nodes of every service of a run.
MAX_NODES = MAX_WORKERS + 8
#: The task service's settings (whoever creates it fixes them).
TASKS_SERVICE = {
    "max_servers": 1,
    "max_clients": MAX_WORKERS,
    "max_nodes": MAX_NODES,
    "max_active_requests_per_client": MAX_ASKING_REQUESTS + 1,
    "max_response_buffer_size": 2,
    "max_loaned_requests": 2,
}
#: The event services' settings.
EVENT_SERVICE = {"max_listeners": MAX_NODES, "max_notifiers": MAX_NODES, "max_nodes": MAX_NODES}
#: The services' names.
TASKS = "tasks"
TO_LEARNER = "to-learner"
TO_WORKERS = "to-workers"
#: The node name of a run's learner (``shared/wire/src/ipc.rs``, ``LEARNER_NODE``).
LEARNER_NODE = "learner"


class WireEnvironment(ctypes.Structure):
    """An environment identity as it crosses the wire (all zeros: none)."""

    _fields_ = [
        ("name", ctypes.c_uint8 * MAX_NAME),
        ("settings", ctypes.c_uint64),
        ("parameters", ctypes.c_uint64 * 3),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return "acps::WireEnvironment"


class WireTask(ctypes.Structure):
    """One task of an answer."""

    _fields_ = [
        ("kind", ctypes.c_uint32),
        ("job", ctypes.c_uint32),
        ("context_len", ctypes.c_uint32),
        ("theta_len", ctypes.c_uint32),
        ("task_id", ctypes.c_uint64),
        ("seed", ctypes.c_uint64),
        ("environment", WireEnvironment),
        ("context", ctypes.c_double * MAX_CONTEXT),
        ("theta", ctypes.c_double * MAX_THETA),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return "acps::WireTask"


class Answer(ctypes.Structure):
    """The header of the learner's answer: what it means, and who answers."""

    _fields_ = [
        ("response", ctypes.c_uint32),
        ("protocol", ctypes.c_uint32),
        ("run", ctypes.c_uint64),
        ("refusal", ctypes.c_uint32),
        ("environments", ctypes.c_uint32),
        ("environment", WireEnvironment),
        ("context_len", ctypes.c_uint32),
        ("theta_len", ctypes.c_uint32),
        ("settings_text_len", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("settings_text", ctypes.c_uint8 * MAX_SETTINGS_TEXT),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return "acps::Answer"


class WireOutcome(ctypes.Structure):
    """One outcome of a worker's message."""

    _fields_ = [
        ("job", ctypes.c_uint32),
        ("ok", ctypes.c_uint32),
        ("task_id", ctypes.c_uint64),
        ("reward", ctypes.c_double),
        ("score", ctypes.c_double),
        ("diagnostics_len", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("diagnostics", ctypes.c_double * MAX_DIAGNOSTICS),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return "acps::WireOutcome"


class WorkerMessage(ctypes.Structure):
    """A worker's request for tasks, carrying the outcomes of tasks it performed."""

    _fields_ = [
        ("protocol", ctypes.c_uint32),
        ("want", ctypes.c_uint32),
        ("run", ctypes.c_uint64),
        ("secret", ctypes.c_uint8 * SECRET_BYTES),
        ("count", ctypes.c_uint32),
        ("slowest_rollout_us", ctypes.c_uint32),
        ("serves_one", ctypes.c_uint32),
        ("context_len", ctypes.c_uint32),
        ("theta_len", ctypes.c_uint32),
        ("settings_text_len", ctypes.c_uint32),
        ("environment", WireEnvironment),
        ("settings_text", ctypes.c_uint8 * MAX_SETTINGS_TEXT),
        ("outcomes", WireOutcome * MAX_BATCH),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 type name of the Rust type."""
        return "acps::WorkerMessage"


#: Every payload type by the name ``acps protocol`` gives it.
PAYLOADS: dict[str, type[ctypes.Structure]] = {
    "WireEnvironment": WireEnvironment,
    "WireTask": WireTask,
    "Answer": Answer,
    "WireOutcome": WireOutcome,
    "WorkerMessage": WorkerMessage,
}
