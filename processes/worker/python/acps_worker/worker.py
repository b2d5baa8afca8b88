"""The worker loop, mirroring the Rust reference worker (``processes/worker/src/lib.rs``): join
the run, keep up to ``in_flight`` tasks in flight in request slots, send outcomes in batches
sized from the measured rollout time, wake the learner only when this worker could run dry,
and watch the learner's liveness while waiting."""

from __future__ import annotations

import contextlib
import ctypes
import enum
import gc
import logging
import math
import os
import signal
import threading
import time
import traceback
import warnings
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from types import FrameType
from typing import TYPE_CHECKING, Any

import iceoryx2 as iox2

from . import _ipc, _wire
from .environment import Environment, shown_settings_text
from .errors import NoLearnerError, ProtocolError, RefusedError

if TYPE_CHECKING:
    from .batch import BatchRollout

log = logging.getLogger("acps_worker")

#: How long blocking waits last before a liveness look (Rust: ``ipc::TICK``).
TICK_MS = 50
#: How often a starting worker looks for the run's learner.
JOIN_POLL = 0.002
#: How long a worker that found the learner looks for the run's secret file before it goes on
#: without (Rust: ``find_secret``).
SECRET_PUBLISHED_WITHIN = 1.0
#: How much simulation one request should carry (Rust: ``BATCH_TIME``).
BATCH_TIME = 800e-6
_U32_MAX = (1 << 32) - 1
_KIND_NAMES = ("train", "evaluate", "baseline")
#: What a rollout that raised leaves as its result.
_RAISED = object()
_TASK_SIZE = ctypes.sizeof(_wire.WireTask)

#: What a rollout returns: ``(reward, score)``, ``(reward, score, diagnostics)`` or ``None`` for a
#: failed rollout.
RolloutResult = tuple[float, float] | tuple[float, float, Sequence[float]] | None


class Task:
    """One rollout to perform: the context, the parameters, the seed of everything random in
    it, and the kind (``"train"``, ``"evaluate"`` or ``"baseline"``)."""

    __slots__ = ("context", "id", "job", "kind", "seed", "theta")

    id: int
    job: int
    kind: str
    seed: int
    context: tuple[float, ...]
    theta: tuple[float, ...]

    def __init__(
        self,
        id: int,
        job: int,
        kind: str,
        seed: int,
        context: tuple[float, ...],
        theta: tuple[float, ...],
    ) -> None:
        """A task of ``job`` with id ``id``."""
        self.id = id
        self.job = job
        self.kind = kind
        self.seed = seed
        self.context = context
        self.theta = theta

    def __repr__(self) -> str:
        """All fields."""
        return (
            f"Task(id={self.id}, job={self.job}, kind={self.kind!r}, seed={self.seed}, "
            f"context={self.context!r}, theta={self.theta!r})"
        )


class Exit(str, enum.Enum):
    """Why a worker stopped."""

    #: The learner said the run is over.
    FINISHED = "finished"
    #: The learner disappeared (crashed or killed).
    LEARNER_GONE = "learner-gone"
    #: The stop flag was set (also by SIGINT or SIGTERM).
    STOPPED = "stopped"


@dataclass(frozen=True)
class Report:
    """What a worker did."""

    #: Why it stopped.
    exit: Exit
    #: Rollouts performed (failed ones included).
    rollouts: int
    #: Rollouts that failed: returned None, raised, or returned non-finite numbers.
    failed: int
    #: Seconds from joining the run to the end (0 when it never joined).
    seconds: float
    #: Seconds spent inside the rollout function.
    rollout_seconds: float


def _next_request(
    queue_depth: int,
    queued: int,
    asked: int,
    outbox: int,
    batch: int,
    free_asking: int | None,
    delivery_free: bool,
) -> tuple[int | None, int] | None:
    """The request a worker sends next, if any: the asking slot it takes (``None``: the
    delivery slot) and the tasks it asks for (Rust: ``next_request``; the cases of
    ``decisions.json`` hold for both)."""
    room = max(queue_depth - (queued + asked), 0)
    flush = outbox > 0 and (outbox >= batch or queued == 0)
    top_up = outbox == 0 and (room >= batch or (asked == 0 and queued == 0))
    if not (flush or top_up) or room == 0:
        return None
    if free_asking is not None:
        return free_asking, min(room, batch)
    if flush and delivery_free:
        return None, 0
    return None


def _wakes_learner(queued: int, batch: int, outbox_full: bool) -> bool:
    """Whether a worker that sent requests wakes the learner: only when it could run dry before
    the learner next looks, or is about to stop simulating (Rust: ``wakes_learner``)."""
    return queued < 2 * batch or outbox_full


class _Batching:
    """Tasks per request from the measured rollout time (Rust: ``Batching``)."""

    __slots__ = ("largest", "mean")

    def __init__(self, in_flight: int) -> None:
        """Batches of at most half of ``in_flight`` (1..=MAX_BATCH), 1 until timed."""
        self.largest = min(max(in_flight // 2, 1), _wire.MAX_BATCH)
        self.mean: float | None = None

    def observe(self, seconds: float) -> None:
        """A rollout took ``seconds``: an exponential mean (weight 0.1)."""
        mean = self.mean
        self.mean = seconds if mean is None else 0.9 * mean + 0.1 * seconds

    def size(self) -> int:
        """Tasks per request: as many as fit BATCH_TIME, within the largest batch."""
        mean = self.mean
        if mean is None:
            return 1
        fits = math.floor(BATCH_TIME / max(mean, 1e-9))
        return max(int(min(fits, self.largest)), 1)


class _Silence:
    """When a waiting worker looks whether the silent learner lives (Rust: ``Silence``)."""

    FIRST_LOOK = 2
    LAST_LOOK = 32
    LIST_EVERY = 8
    __slots__ = ("look_after", "looks", "waits")

    def __init__(self) -> None:
        """A learner just heard."""
        self.heard()

    def heard(self) -> None:
        """The learner woke this worker: start over."""
        self.waits = 0
        self.look_after = self.FIRST_LOOK
        self.looks = 0

    def look_due(self) -> bool:
        """A wait timed out; True when the learner should be looked at now."""
        self.waits += 1
        return self.waits >= self.look_after

    def lists(self) -> bool:
        """Whether the due look lists the run's nodes rather than trust the learner's PID."""
        return self.looks % self.LIST_EVERY == self.LIST_EVERY - 1

    def looked(self) -> None:
        """The look found the learner alive: look again after twice as many silent waits."""
        self.waits = 0
        self.looks += 1
        self.look_after = min(2 * self.look_after, self.LAST_LOOK)


def _needs(answer: _wire.Answer) -> str:
    """What a refusal says the learner's jobs need, in words (Rust: ``Answer::needs``)."""
    spec = Environment.from_wire(answer.environment)
    if spec is None:
        return "no environment"
    text = shown_settings_text(int(answer.settings_text_len), bytes(answer.settings_text))
    n = int(answer.environments)
    if n <= 1:
        return f"{spec}{text}"
    if n == 2:
        return f"{spec}{text} and 1 other"
    return f"{spec}{text} and {n - 1} others"


def _sizes(context: int, theta: int) -> str:
    """Sizes in words, as Rust's ``Sizes`` displays them."""
    return f"contexts of {context} and parameters of {theta} values"


def refusal_reason(
    answer: _wire.Answer,
    identity: int,
    serves: Environment,
    protocol: int,
    sizes: tuple[int, int] | None = None,
    origin: str = "",
) -> str:
    """Why the learner's ``answer`` refused this worker (of run ``identity``, 0 before it learnt
    one, serving ``serves`` of ``sizes``, speaking ``protocol``, with the secret from
    ``origin``), naming both sides exactly as the Rust worker's ``refusal_reason`` does."""
    if answer.protocol != protocol:
        return f"protocol version {protocol} here, {answer.protocol} at the learner (another build)"
    if answer.refusal == _wire.REFUSAL_SECRET:
        return (
            f"its messages do not carry the run's secret: {origin}; a worker started by hand "
            f"reads the file the learner writes, or takes the secret in {_wire.SECRET_ENV}"
        )
    if answer.refusal == _wire.REFUSAL_ENVIRONMENT:
        return f"this worker serves {serves.shown()}; the run's jobs need {_needs(answer)}"
    if answer.refusal == _wire.REFUSAL_SIZES:
        needed = _sizes(int(answer.context_len), int(answer.theta_len))
        if sizes is None:
            return f"the run's jobs need {needed}"
        return f"this worker serves {_sizes(*sizes)}; the run's jobs need {needed}"
    return (
        f"this worker belongs to run identity {identity:016x}, the learner runs {answer.run:016x}"
    )


def _copy(ctype: type[Any], address: int) -> Any:
    """A private copy of the ``ctype`` value at ``address`` (shared memory)."""
    value = ctype()
    ctypes.memmove(ctypes.addressof(value), address, ctypes.sizeof(ctype))
    return value


def _first_foreign(tasks: ctypes.Array[_wire.WireTask], served: bytes) -> int | None:
    """The index of the first of ``tasks`` that is not for the environment whose wire bytes
    are ``served``, if any."""
    for i, wire in enumerate(tasks):
        if bytes(wire.environment) != served:
            return i
    return None


@dataclass
class _Ports:
    """Everything of iceoryx2 a worker holds, released in reverse order of creation."""

    node: Any = None
    tasks: Any = None
    to_learner: Any = None
    to_workers: Any = None
    client: Any = None
    notifier: Any = None
    listener: Any = None

    def release(self, pending: list[Any]) -> None:
        """Release the ``pending`` requests, the ports, the services and the node, in that
        order (a Python process that just exits leaves iceoryx2's files behind)."""
        for request in pending:
            _delete(request)
        for port in (self.listener, self.notifier, self.client):
            _delete(port)
        self.listener = self.notifier = self.client = None
        self.to_workers = self.to_learner = self.tasks = None
        self.node = None
        gc.collect()


def _delete(port: Any) -> None:
    """Release an iceoryx2 object now."""
    if port is not None:
        try:
            port.delete()
        except Exception as error:  # noqa: BLE001 - releasing must go on
            log.debug("releasing %r failed: %s", port, error)


@contextlib.contextmanager
def _signals(stop: threading.Event, enabled: bool) -> Iterator[None]:
    """SIGINT and SIGTERM set ``stop`` while the worker serves (main thread only), so that it
    ends cleanly; the previous handlers come back afterwards."""
    if not enabled or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        """Set the stop flag."""
        log.info("signal %d: the worker stops", signum)
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


Rollout = Callable[[Task], RolloutResult]


def serve(
    rollout: Rollout | None = None,
    run: str | None = None,
    *,
    batch_rollout: BatchRollout | None = None,
    environment: Environment | None = None,
    sizes: tuple[int, int] | None = None,
    queue_depth: int = _wire.DEFAULT_QUEUE_DEPTH,
    in_flight: int | None = None,
    name: str | None = None,
    startup_timeout: float = 10.0,
    stop: threading.Event | None = None,
    handle_signals: bool = True,
    _protocol: int | None = None,
) -> Report:
    """Serve the learner of ``run`` (default: ``$ACPS_RUN``) until it finishes, disappears or
    ``stop`` is set (SIGINT and SIGTERM set it when ``handle_signals`` and this is the main
    thread), and return what this worker did.

    ``rollout(task)`` returns ``(reward, score)``, optionally with a third value, a sequence
    of up to 16 diagnostics; ``None``, an exception or non-finite numbers make a failed
    outcome (the first exception is logged with its traceback).

    ``batch_rollout(batch)`` instead (vectorised simulators; needs numpy) receives every task
    the worker holds that shares the first one's shapes, as a :class:`TaskBatch` of numpy
    arrays, and returns arrays ``(rewards, scores)`` or ``(rewards, scores, ok)``; an exception
    or a result of the wrong shape fails the whole batch, a false ``ok`` or a non-finite number
    its task. A batch holds at most 64 tasks (the outcomes of one request) and at most what the
    worker keeps queued (``queue_depth``), and the learner's window (its ``in_flight``) bounds
    how many tasks exist at once: a batch worker wants a ``queue_depth`` of at least the
    window's share of each worker. ``sizes=(n_context, n_theta)`` declares the lengths of
    contexts and parameters the simulator takes: the learner refuses the worker at once
    (:class:`RefusedError` naming both sides' sizes) when its problem has others, where a
    worker that declares none would fail every rollout. ``environment`` is the
    identity this worker serves (default :meth:`Environment.unnamed`, which matches only
    problems that name none). ``queue_depth`` (1..=128) tasks are kept asked for or queued: the
    worker's queue, not the learner's window (``in_flight``, its old name, still works with a
    :class:`DeprecationWarning`).

    Raises :class:`NoLearnerError` when no learner comes within ``startup_timeout`` seconds,
    :class:`RefusedError` when the learner refuses this worker, :class:`ProtocolError` for a
    task of another environment or diagnostics beyond the wire's capacity, and
    :class:`AcpsWorkerError` when iceoryx2 fails. Every iceoryx2 resource is released before
    it returns or raises.
    """
    if (rollout is None) == (batch_rollout is None):
        raise TypeError("serve needs exactly one of rollout and batch_rollout")
    run = run if run is not None else os.environ.get(_wire.RUN_ENV)
    if not run:
        raise ValueError(f"no run to join: pass run=NAME or set {_wire.RUN_ENV}")
    _ipc.check_run_name(run)
    option = "queue_depth"
    if in_flight is not None:
        warnings.warn(
            "serve(in_flight=...) is deprecated: use queue_depth (a worker's queue, not the "
            "learner's window)",
            DeprecationWarning,
            stacklevel=2,
        )
        option, queue_depth = "in_flight", in_flight
    if isinstance(queue_depth, bool) or not isinstance(queue_depth, int):
        raise TypeError(f"worker option {option} must be an int, got {queue_depth!r}")
    if not 1 <= queue_depth <= _wire.MAX_IN_FLIGHT_PER_WORKER:
        raise ValueError(
            f"worker option {option} must be in 1..={_wire.MAX_IN_FLIGHT_PER_WORKER}, "
            f"got {queue_depth}"
        )
    name = _ipc.check_worker_name(name if name is not None else f"worker-{os.getpid()}")
    if sizes is not None and not (
        len(sizes) == 2 and 1 <= sizes[0] <= _wire.MAX_CONTEXT and 0 <= sizes[1] <= _wire.MAX_THETA
    ):
        raise ValueError(
            f"worker option sizes must be (n_context in 1..={_wire.MAX_CONTEXT}, "
            f"n_theta in 0..={_wire.MAX_THETA}), got {sizes!r}"
        )
    if not startup_timeout >= 0:
        raise ValueError(f"startup_timeout must be >= 0 seconds, got {startup_timeout}")
    session = _Session(
        run=run,
        rollout=rollout,
        batch_rollout=batch_rollout,
        environment=environment if environment is not None else Environment.unnamed(),
        sizes=sizes,
        in_flight=queue_depth,
        name=name,
        startup_timeout=startup_timeout,
        stop=stop if stop is not None else threading.Event(),
        protocol=_wire.PROTOCOL_VERSION if _protocol is None else _protocol,
    )
    with _signals(session.stop, handle_signals):
        try:
            return session.serve()
        finally:
            session.close()


class _Session:
    """One worker's state while it serves."""

    def __init__(
        self,
        *,
        run: str,
        rollout: Rollout | None,
        batch_rollout: BatchRollout | None,
        environment: Environment,
        sizes: tuple[int, int] | None,
        in_flight: int,
        name: str,
        startup_timeout: float,
        stop: threading.Event,
        protocol: int,
    ) -> None:
        """A worker of ``run`` that is yet to open anything (see :func:`serve`)."""
        self.run = run
        self.rollout = rollout
        self.batch_rollout = batch_rollout
        self.environment = environment
        self.sizes = sizes
        self.in_flight = in_flight
        self.name = name
        self.startup_timeout = startup_timeout
        self.stop = stop
        self.protocol = protocol
        self.config = _ipc.run_config(run)
        self.ports = _Ports()
        # Requests in flight with the number of tasks each asks for; None is a free slot. The
        # first slots ask for tasks, the last only delivers outcomes (see `loop`).
        self.slots: list[tuple[Any, int] | None] = []
        self.learner_pid: int | None = None
        self.rollouts = 0
        self.failed = 0
        self.rollout_seconds = 0.0
        self.joined: float | None = None
        self.logged_failure = False
        self.secret: bytes | None = None
        self.secret_origin = ""

    def report(self, exit: Exit) -> Report:
        """What the worker did, ending for ``exit``."""
        seconds = 0.0 if self.joined is None else time.perf_counter() - self.joined
        return Report(exit, self.rollouts, self.failed, seconds, self.rollout_seconds)

    def close(self) -> None:
        """Release everything, then remove the run's files if no node of the run lives."""
        self.ports.release([slot[0] for slot in self.slots if slot is not None])
        self.slots.clear()
        _ipc.remove_run_files_if_last(self.run)

    def open(self) -> None:
        """The node and the run's services, opened with the limits every side agrees on."""
        ports = self.ports
        _ipc.check_owner(self.run, self.name)
        _ipc.own_root(self.run)
        try:
            ports.node = (
                iox2.NodeBuilder.new()
                .name(iox2.NodeName.new(self.name))
                .config(self.config)
                .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                .create(iox2.ServiceType.Ipc)
            )
        except Exception as error:
            raise _ipc.ipc_error(
                f"creating node '{self.name}' of run '{self.run}'", error
            ) from error
        settings = _wire.TASKS_SERVICE
        try:
            ports.tasks = (
                ports.node.service_builder(iox2.ServiceName.new(_wire.TASKS))
                .request_response(_wire.WorkerMessage, iox2.Slice[_wire.WireTask])
                .response_header(_wire.Answer)
                .max_servers(settings["max_servers"])
                .max_clients(settings["max_clients"])
                .max_nodes(settings["max_nodes"])
                .max_active_requests_per_client(settings["max_active_requests_per_client"])
                .max_response_buffer_size(settings["max_response_buffer_size"])
                .max_loaned_requests(settings["max_loaned_requests"])
                .open_or_create()
            )
        except Exception as error:
            raise _ipc.open_error("opening the task service", error) from error

        def event(service: str) -> Any:
            limits = _wire.EVENT_SERVICE
            try:
                return (
                    ports.node.service_builder(iox2.ServiceName.new(service))
                    .event()
                    .max_listeners(limits["max_listeners"])
                    .max_notifiers(limits["max_notifiers"])
                    .max_nodes(limits["max_nodes"])
                    .open_or_create()
                )
            except Exception as error:
                raise _ipc.open_error(f"opening the event service '{service}'", error) from error

        ports.to_learner = event(_wire.TO_LEARNER)
        ports.to_workers = event(_wire.TO_WORKERS)

    def join(self) -> bool:
        """Wait for the run's learner; False when stopped first."""
        started = time.monotonic()
        while self.ports.tasks.dynamic_config.number_of_servers == 0:
            if self.stop.is_set():
                return False
            waited = time.monotonic() - started
            if waited > self.startup_timeout:
                raise NoLearnerError(self.run, waited)
            time.sleep(JOIN_POLL)
        ports = self.ports
        try:
            ports.client = ports.tasks.client_builder().create()
            ports.notifier = ports.to_learner.notifier_builder().create()
            ports.listener = ports.to_workers.listener_builder().create()
        except Exception as error:
            raise _ipc.ipc_error("creating the worker's ports", error) from error
        self.learner_pid = _ipc.alive_learner_pid(self.config)
        self.find_secret(started)
        log.info("worker %s joins run '%s'", self.name, self.run)
        return True

    def find_secret(self, started: float) -> None:
        """The run's secret and where it came from (Rust: ``find_secret``): the learner writes
        its file just after it starts serving, so a worker that found the learner a moment
        earlier looks again for a little while before it goes on without one."""
        looking = time.monotonic()
        while True:
            self.secret, self.secret_origin = _ipc.find_secret(self.run)
            now = time.monotonic()
            waited_enough = (
                now - looking >= SECRET_PUBLISHED_WITHIN or now - started >= self.startup_timeout
            )
            if self.secret is not None or waited_enough or self.stop.is_set():
                return
            time.sleep(JOIN_POLL)

    def learner_lives(self, listing: bool) -> bool:
        """Whether the learner lives: its process by PID (cheap) unless ``listing``, else (or
        when the PID's process is gone) by listing the run's nodes for a live learner node."""
        if self.ports.tasks.dynamic_config.number_of_servers == 0:
            return False
        if not listing and self.learner_pid is not None and _ipc.process_runs(self.learner_pid):
            return True
        self.learner_pid = _ipc.alive_learner_pid(self.config)
        return self.learner_pid is not None

    def failure(self, task_id: int, job: int, why: str, exc: bool = False) -> None:
        """Count a failed rollout; log the first with its reason (and the traceback of the
        exception being handled when ``exc``, as text: a record holding the traceback itself
        would keep this worker's frames, and with them its shared memory, alive)."""
        self.failed += 1
        if not self.logged_failure:
            self.logged_failure = True
            trace = "\n" + traceback.format_exc().rstrip() if exc else ""
            log.error(
                "rollout of task %d (job %d) failed: %s; later failures are counted, not logged%s",
                task_id,
                job,
                why,
                trace,
            )

    def serve(self) -> Report:
        """Open, join and serve until the run ends for this worker."""
        self.open()
        if not self.join():
            return self.report(Exit.STOPPED)
        self.joined = time.perf_counter()
        return self.loop()

    def loop(self) -> Report:
        """The Rust worker's loop: send requests while the budget allows, wake the learner
        when this worker could run dry, take answers when the queue is empty, simulate one
        task, else wait a tick for the learner and look whether it lives when it stays
        silent."""
        ports = self.ports
        client, notifier, listener = ports.client, ports.notifier, ports.listener
        in_flight = self.in_flight
        stop = self.stop
        rollout = self.rollout
        batches: Any = None
        queue: Any = deque()
        if self.batch_rollout is not None:
            from . import batch as batches

            queue = batches.TaskQueue()
            served_array = batches.environment_bytes(bytes(self.environment.to_wire()))
        served = self.environment.to_wire()
        served_bytes = bytes(served)
        identity = 0
        asking = min(in_flight, _wire.MAX_ASKING_REQUESTS)
        slots = self.slots = [None] * (asking + 1)
        outbox = _wire.WorkerMessage()
        outbox.protocol = self.protocol
        if self.secret is not None:
            ctypes.memmove(outbox.secret, self.secret, len(self.secret))
        outbox.serves_one = 1
        outbox.environment = served
        outbox.settings_text_len, text = self.environment.settings_text_to_wire()
        ctypes.memmove(outbox.settings_text, text, len(text))
        if self.sizes is not None:
            outbox.context_len, outbox.theta_len = self.sizes
        outcomes = outbox.outcomes
        outcome_rows = None if batches is None else batches.outcome_view(outcomes)
        count = 0
        batching = _Batching(in_flight)
        slowest_us = 0
        silence = _Silence()
        unannounced = False
        tick = iox2.Duration.from_millis(TICK_MS)
        perf = time.perf_counter
        isfinite = math.isfinite
        while True:
            if stop.is_set():
                return self.report(Exit.STOPPED)
            sent = False
            while True:
                asked = 0
                free = None
                for i, slot in enumerate(slots):
                    if slot is not None:
                        asked += slot[1]
                    elif free is None and i < asking:
                        free = i
                request = _next_request(
                    in_flight,
                    len(queue),
                    asked,
                    count,
                    batching.size(),
                    free,
                    slots[asking] is None,
                )
                if request is None:
                    break
                index, want = request
                if index is None:
                    index = asking
                outbox.run = identity
                outbox.want = want
                outbox.count = count
                outbox.slowest_rollout_us = slowest_us
                try:
                    pending = client.send_copy(outbox)
                except Exception as error:
                    raise _ipc.ipc_error("sending a request", error) from error
                slots[index] = (pending, want)
                count = 0
                sent = True
            unannounced |= sent
            outbox_full = count >= _wire.MAX_BATCH
            if unannounced and _wakes_learner(len(queue), batching.size(), outbox_full):
                try:
                    notifier.notify()
                except Exception as error:
                    raise _ipc.ipc_error("waking the learner", error) from error
                unannounced = False
            if not queue or outbox_full:
                for i, slot in enumerate(slots):
                    if slot is None:
                        continue
                    pending = slot[0]
                    try:
                        response = pending.receive()
                    except Exception as error:
                        raise _ipc.ipc_error("receiving a response", error) from error
                    if response is None:
                        continue
                    answer = _copy(_wire.Answer, response.user_header_ptr)
                    code = answer.response
                    if code == _wire.RESPONSE_TASK:
                        if identity == 0:
                            identity = int(answer.run)
                        payload = response.payload()
                        # The binding reports the slice's length in bytes, not tasks, for a
                        # slice whose element type it only knows by its size.
                        size = payload.len()
                        n, rest = divmod(size, _TASK_SIZE)
                        if rest or n > _wire.MAX_BATCH:
                            raise ProtocolError(
                                f"an answer of {size} bytes is no whole number of "
                                f"{_TASK_SIZE}-byte tasks up to {_wire.MAX_BATCH}"
                            )
                        if n:
                            tasks = _copy(_wire.WireTask * n, payload.as_ptr())
                            if batches is None:
                                foreign = _first_foreign(tasks, served_bytes)
                                if foreign is None:
                                    queue.extend(tasks)
                            else:
                                foreign = queue.extend(tasks, served_array)
                            if foreign is not None:
                                wire = tasks[foreign]
                                raise ProtocolError(
                                    f"task {wire.task_id} of job {wire.job} needs environment "
                                    f"{Environment.from_wire(wire.environment)}, this worker "
                                    f"serves {self.environment}"
                                )
                    elif code == _wire.RESPONSE_STOP:
                        _delete(response)
                        return self.report(Exit.FINISHED)
                    else:
                        _delete(response)
                        raise RefusedError(
                            self.run,
                            refusal_reason(
                                answer,
                                identity,
                                self.environment,
                                self.protocol,
                                self.sizes,
                                self.secret_origin,
                            ),
                        )
                    # The answered request must be gone before the next is sent: the service
                    # allows only so many active requests per client.
                    _delete(response)
                    _delete(pending)
                    slots[i] = None
            if queue and not outbox_full and batches is not None:
                count, took = self.perform_batch(batches, queue, outcome_rows, count, batching)
                # Every task of the batch waited for all of it.
                slowest_us = max(slowest_us, min(int(took * 1e6), _U32_MAX))
                silence.heard()
                continue
            if queue and not outbox_full:
                assert rollout is not None
                wire = queue.popleft()
                n_context = min(wire.context_len, _wire.MAX_CONTEXT)
                n_theta = min(wire.theta_len, _wire.MAX_THETA)
                kind = wire.kind
                task = Task(
                    wire.task_id,
                    wire.job,
                    _KIND_NAMES[kind] if kind < 3 else "train",
                    wire.seed,
                    tuple(wire.context[:n_context]),
                    tuple(wire.theta[:n_theta]),
                )
                started = perf()
                result: Any
                try:
                    result = rollout(task)
                except Exception:  # noqa: BLE001 - any failure of a rollout is a failed outcome
                    self.failure(task.id, task.job, "the rollout raised", exc=True)
                    result = _RAISED
                took = perf() - started
                batching.observe(took)
                self.rollout_seconds += took
                us = int(took * 1e6)
                if us > slowest_us:
                    slowest_us = min(us, _U32_MAX)
                self.rollouts += 1
                outcome = outcomes[count]
                outcome.job = wire.job
                outcome.task_id = wire.task_id
                outcome.diagnostics_len = 0
                ok = 0
                if result is None:
                    self.failure(task.id, task.job, "it returned None")
                elif result is not _RAISED:
                    ok = self.fill(task, outcome, result, isfinite)
                outcome.ok = ok
                if not ok:
                    outcome.reward = 0.0
                    outcome.score = 0.0
                    outcome.diagnostics_len = 0
                count += 1
                silence.heard()
                continue
            try:
                woken = listener.timed_wait(tick)
            except iox2.ListenerWaitError as error:
                # A signal, also a pause and resume: only the stop flag ends the worker.
                if "Interrupt" not in str(error) and "Interrupt" not in repr(error):
                    raise _ipc.ipc_error("waiting for the learner", error) from error
                woken = []
            if woken:
                silence.heard()
            elif silence.look_due():
                if not self.learner_lives(silence.lists()):
                    log.warning("the learner of run '%s' is gone", self.run)
                    return self.report(Exit.LEARNER_GONE)
                silence.looked()

    def perform_batch(
        self, batches: Any, queue: Any, outcome_rows: Any, count: int, batching: _Batching
    ) -> tuple[int, float]:
        """Perform the front of ``queue`` with one call of the batch rollout, writing the
        outcomes after the ``count`` already in the outbox; returns the new count and the
        seconds the call took."""
        np = batches.np
        rows = queue.take(_wire.MAX_BATCH - count)
        n = len(rows)
        tasks = batches.batch_of(rows)
        logged = False
        started = time.perf_counter()
        try:
            result = self.batch_rollout(tasks)  # type: ignore[misc]
        except Exception:  # noqa: BLE001 - any failure of a rollout is a failed outcome
            took = time.perf_counter() - started
            why = f"the batch rollout of {n} tasks raised"
            # Here, where the traceback is the one being handled.
            self.failure(int(tasks.ids[0]), int(tasks.jobs[0]), why, exc=True)
            logged = True
        else:
            took = time.perf_counter() - started
            rewards, scores, ok, why = batches.checked(result, n)
        if why is not None:
            rewards = scores = None
            ok = np.zeros(n, dtype=bool)
        batching.observe(took / n)
        self.rollout_seconds += took
        self.rollouts += n
        failed = n - int(ok.sum())
        if failed:
            if not logged:
                first = int(np.argmin(ok))
                self.failure(
                    int(tasks.ids[first]),
                    int(tasks.jobs[first]),
                    why
                    or f"{failed} of a batch of {n} tasks failed (ok false, or non-finite numbers)",
                )
            # failure() counted one.
            self.failed += failed - 1
        batches.write(outcome_rows[count : count + n], rows, rewards, scores, ok)
        return count + n, took

    def fill(
        self,
        task: Task,
        outcome: _wire.WireOutcome,
        result: Any,
        isfinite: Callable[[float], bool],
    ) -> int:
        """Write ``result`` into ``outcome``; 1 when it is a valid ok outcome, 0 (counted and
        logged as failed) when not. Too many diagnostics raise :class:`ProtocolError`."""
        try:
            if len(result) == 2:
                reward, score = result
                diagnostics: Sequence[float] = ()
            elif len(result) == 3:
                reward, score, diagnostics = result
            else:
                raise TypeError(f"{len(result)} values")
            reward = float(reward)
            score = float(score)
            n = len(diagnostics)
        except (TypeError, ValueError) as error:
            self.failure(
                task.id,
                task.job,
                f"it returned {result!r} ({error}); a rollout returns (reward, score), "
                "(reward, score, diagnostics) or None",
            )
            return 0
        if n > _wire.MAX_DIAGNOSTICS:
            raise ProtocolError(
                f"task {task.id} of job {task.job}: the outcome cannot be sent: an outcome's "
                f"diagnostics has {n} values, the wire carries at most {_wire.MAX_DIAGNOSTICS} "
                "(MAX_DIAGNOSTICS)"
            )
        if not (isfinite(reward) and isfinite(score)):
            self.failure(task.id, task.job, f"non-finite reward {reward} or score {score}")
            return 0
        if n:
            try:
                values = [float(d) for d in diagnostics]
            except (TypeError, ValueError) as error:
                self.failure(
                    task.id, task.job, f"diagnostics {diagnostics!r} are not numbers ({error})"
                )
                return 0
            if not all(isfinite(v) for v in values):
                self.failure(task.id, task.job, f"non-finite diagnostics {values}")
                return 0
            outcome.diagnostics[:n] = values
            outcome.diagnostics_len = n
        outcome.reward = reward
        outcome.score = score
        return 1
