"""The ctypes mirror against the layout the Rust build prints (`acps protocol`)."""

from __future__ import annotations

import ctypes
import importlib.metadata
import json
import unittest
from typing import Any

from acps_worker import _ipc, _wire

from .support import acps

_ELEMENTS: dict[str, type[Any]] = {
    "u8": ctypes.c_uint8,
    "u32": ctypes.c_uint32,
    "u64": ctypes.c_uint64,
    "f64": ctypes.c_double,
}


def element_name(ctype: type[Any]) -> str:
    """The layout's name of a ctypes element type: u8/u32/u64/f64 or a payload's name."""
    for name, candidate in _ELEMENTS.items():
        if ctype is candidate:
            return name
    for name, payload in _wire.PAYLOADS.items():
        if ctype is payload:
            return name
    raise AssertionError(f"{ctype} is no type of the wire")


class LayoutTest(unittest.TestCase):
    """Every payload, limit, code and service setting equals the Rust build's."""

    layout: dict[str, Any]

    @classmethod
    def setUpClass(cls) -> None:
        """Ask the Rust build for its layout."""
        cls.layout = json.loads(acps("protocol"))

    def test_every_payload_has_rusts_name_size_alignment_and_fields(self) -> None:
        """Type names, sizes, alignments, field order, offsets, sizes, element types, lengths."""
        described = {t["name"] for t in self.layout["types"]}
        self.assertEqual(described, set(_wire.PAYLOADS), "the same payload types")
        for rust in self.layout["types"]:
            with self.subTest(payload=rust["name"]):
                ours = _wire.PAYLOADS[rust["name"]]
                type_name: Any = getattr(ours, "type_name")  # noqa: B009 - a static method
                self.assertEqual(type_name(), rust["type_name"])
                self.assertEqual(ctypes.sizeof(ours), rust["size"])
                self.assertEqual(ctypes.alignment(ours), rust["align"])
                fields = ours._fields_
                self.assertEqual(
                    [f[0] for f in fields],
                    [f["name"] for f in rust["fields"]],
                    "the fields in Rust's order",
                )
                declared: list[tuple[str, Any]] = [(f[0], f[1]) for f in fields]
                for (name, ctype), field in zip(declared, rust["fields"], strict=True):
                    descriptor = getattr(ours, name)
                    self.assertEqual(descriptor.offset, field["offset"], name)
                    self.assertEqual(descriptor.size, field["size"], name)
                    if issubclass(ctype, ctypes.Array):
                        self.assertEqual(ctype._length_, field["len"], name)
                        self.assertEqual(element_name(ctype._type_), field["type"], name)
                        self.assertEqual(ctypes.alignment(ctype._type_), field["align"], name)
                    else:
                        self.assertIsNone(field["len"], name)
                        self.assertEqual(element_name(ctype), field["type"], name)
                        self.assertEqual(ctypes.alignment(ctype), field["align"], name)

    def test_limits_codes_and_protocol_are_rusts(self) -> None:
        """The capacities, the answer/refusal/kind codes and the protocol version."""
        self.assertEqual(self.layout["protocol"], _wire.PROTOCOL_VERSION)
        for name, value in self.layout["limits"].items():
            self.assertEqual(getattr(_wire, name), value, name)
        codes = self.layout["codes"]
        self.assertEqual(codes["kind"], _wire.KINDS)
        self.assertEqual(
            codes["response"],
            {
                "task": _wire.RESPONSE_TASK,
                "stop": _wire.RESPONSE_STOP,
                "refused": _wire.RESPONSE_REFUSED,
            },
        )
        self.assertEqual(
            codes["refusal"],
            {
                "protocol": _wire.REFUSAL_PROTOCOL,
                "run": _wire.REFUSAL_RUN,
                "environment": _wire.REFUSAL_ENVIRONMENT,
                "sizes": _wire.REFUSAL_SIZES,
                "secret": _wire.REFUSAL_SECRET,
            },
        )

    def test_services_are_opened_with_rusts_settings(self) -> None:
        """Service settings, prefix, creation timeout, and the iceoryx2 version installed."""
        services = self.layout["services"]
        self.assertEqual(services["run_env"], _wire.RUN_ENV)
        self.assertEqual(services["secret_env"], _wire.SECRET_ENV)
        self.assertEqual(services["secret_file"], _wire.SECRET_FILE)
        self.assertEqual(services["prefix"], _wire.PREFIX_FORMAT)
        self.assertEqual(services["root"], _wire.ROOT_FORMAT)
        self.assertEqual(services["creation_timeout_ms"], _wire.CREATION_TIMEOUT_MS)
        tasks = dict(services["tasks"])
        self.assertEqual(
            (tasks.pop("pattern"), tasks.pop("request"), tasks.pop("request_header")),
            ("request-response", "WorkerMessage", "()"),
        )
        self.assertEqual(
            (tasks.pop("response"), tasks.pop("response_header")), ("[WireTask]", "Answer")
        )
        # The server's setting: a worker opens no server.
        self.assertEqual(tasks.pop("initial_max_slice_len"), _wire.MAX_BATCH)
        self.assertEqual(tasks, _wire.TASKS_SERVICE)
        self.assertEqual(services[_wire.TO_LEARNER], _wire.EVENT_SERVICE)
        self.assertEqual(services[_wire.TO_WORKERS], _wire.EVENT_SERVICE)
        self.assertEqual(importlib.metadata.version("iceoryx2"), self.layout["iceoryx2"])

    def test_failures_to_open_a_service_say_what_happened(self) -> None:
        """iceoryx2's reasons in the words the Rust worker uses; an unknown one stays as it is."""
        cases = [
            ("HangsInCreation", "died while creating it"),
            ("DoesNotExist", "removed while this process opened it"),
            ("IsMarkedForDestruction", "creating or removing it at the same moment"),
            ("ExceedsMaxNumberOfNodes", "the most processes a run has"),
            ("IncompatibleRequestOrResponseType", "another acps build"),
            ("VersionMismatch", "another acps build"),
            ("SomethingNew", "RuntimeError: SomethingNew"),
        ]
        for reason, words in cases:
            with self.subTest(reason=reason):
                error = _ipc.open_error("opening the task service", RuntimeError(reason))
                self.assertIn(words, str(error))
                self.assertTrue(str(error).startswith("opening the task service: "))


if __name__ == "__main__":
    unittest.main()
