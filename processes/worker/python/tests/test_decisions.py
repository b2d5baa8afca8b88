"""The Python worker's loop follows the decisions Rust's does: both are tested against the
cases of ``processes/worker/decisions.json`` (requests, wake-ups, batch sizes, looks at a
silent learner)."""

from __future__ import annotations

import json
import unittest
from pathlib import Path
from typing import Any

from acps_worker import _wire, worker

TABLE = Path(__file__).resolve().parents[2] / "decisions.json"


class DecisionsTest(unittest.TestCase):
    table: dict[str, Any]

    @classmethod
    def setUpClass(cls) -> None:
        cls.table = json.loads(TABLE.read_text())

    def test_requests(self) -> None:
        for case in self.table["requests"]["cases"]:
            with self.subTest(case["name"]):
                self.assertEqual(len(case["slots"]), _wire.MAX_ASKING_REQUESTS)
                slots: list[int | None] = list(case["slots"])
                delivery: int | None = case["delivery"]
                outbox = case["outbox"]
                sent = []
                while True:
                    free = next((i for i, want in enumerate(slots) if want is None), None)
                    asked = sum(w for w in [*slots, delivery] if w is not None)
                    request = worker._next_request(
                        case["queue_depth"],
                        case["queued"],
                        asked,
                        outbox,
                        case["batch"],
                        free,
                        delivery is None,
                    )
                    if request is None:
                        break
                    slot, want = request
                    if slot is None:
                        delivery = want
                        sent.append([_wire.MAX_ASKING_REQUESTS, want])
                    else:
                        slots[slot] = want
                        sent.append([slot, want])
                    outbox = 0
                self.assertEqual(sent, case["sent"])

    def test_wake_ups(self) -> None:
        for case in self.table["wakes_learner"]["cases"]:
            with self.subTest(case=case):
                self.assertEqual(
                    worker._wakes_learner(case["queued"], case["batch"], case["outbox_full"]),
                    case["wakes"],
                )

    def test_batch_sizes(self) -> None:
        for case in self.table["batch_size"]["cases"]:
            with self.subTest(case=case):
                batching = worker._Batching(case["queue_depth"])
                for ns in case["rollouts_ns"]:
                    batching.observe(ns * 1e-9)
                self.assertEqual(batching.size(), case["size"])

    def test_looks_at_a_silent_learner(self) -> None:
        silence = worker._Silence()
        looks = []
        for wait in range(1, self.table["silence"]["waits"] + 1):
            if silence.look_due():
                looks.append([wait, silence.lists()])
                silence.looked()
        self.assertEqual(looks, self.table["silence"]["looks"])


if __name__ == "__main__":
    unittest.main()
