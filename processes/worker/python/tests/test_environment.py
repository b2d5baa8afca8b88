"""Environment identities as Rust computes them."""

from __future__ import annotations

import unittest

from acps_worker import Environment, fnv1a
from acps_worker.environment import FNV_OFFSET


class EnvironmentTest(unittest.TestCase):
    """FNV-1a and EnvironmentSpec::from_text compatibility."""

    def test_fnv1a_matches_the_published_test_vectors(self) -> None:
        """The vectors of shared/src/fnv.rs."""
        self.assertEqual(fnv1a(b""), 0xCBF29CE484222325)
        self.assertEqual(fnv1a(b"a"), 0xAF63DC4C8601EC8C)
        self.assertEqual(fnv1a(b"foobar"), 0x85944171F73967E8)
        self.assertEqual(fnv1a(b"bar", fnv1a(b"foo")), fnv1a(b"foobar"))
        self.assertEqual(FNV_OFFSET, fnv1a(b""))

    def test_text_settings_hash_like_from_text(self) -> None:
        """The doc example of EnvironmentSpec::from_text, and UTF-8 bytes."""
        spec = Environment("reach-2d", settings="dt=0.01", parameters=(1, 0, 0))
        self.assertEqual(str(spec), "reach-2d [1, 0, 0] (settings 30178b206d634ad5)")
        self.assertEqual(Environment("a", "é").settings, fnv1a("é".encode()))
        self.assertEqual(Environment("a", 0x30178B206D634AD5), Environment("a", "dt=0.01"))
        self.assertNotEqual(Environment("a", "x", (1, 0, 0)), Environment("a", "x", (2, 0, 0)))

    def test_unnamed_matches_only_itself(self) -> None:
        """The unnamed identity: name 'unnamed', parameters 0, the hash of no text."""
        unnamed = Environment.unnamed()
        self.assertEqual(
            (unnamed.name, unnamed.settings, unnamed.parameters), ("unnamed", FNV_OFFSET, (0, 0, 0))
        )
        self.assertTrue(unnamed.is_unnamed())
        self.assertEqual(str(unnamed), "no named environment")
        self.assertFalse(Environment("unnamed", "x").is_unnamed())

    def test_the_wire_carries_an_identity_both_ways(self) -> None:
        """Name padded with zeros, settings and parameters."""
        spec = Environment("bowl", "bowl v1", (1, 2, 2**64 - 1))
        wire = spec.to_wire()
        self.assertEqual(bytes(wire.name), b"bowl" + bytes(28))
        self.assertEqual(Environment.from_wire(wire), spec)
        wire.name[5] = ord("x")
        self.assertIsNone(Environment.from_wire(wire), "characters behind the padding")

    def test_bad_identities_are_refused(self) -> None:
        """Names, hashes and parameters outside what Rust accepts."""
        for name in ["", "with space", "ünïcode", "x" * 33]:
            with self.assertRaisesRegex(ValueError, "must be 1 to 32 characters"):
                Environment(name)
        with self.assertRaisesRegex(ValueError, "not a u64"):
            Environment("a", 2**64)
        with self.assertRaisesRegex(ValueError, "three u64"):
            Environment("a", "", (1, 2))
        with self.assertRaises(TypeError):
            Environment("a", 1.5)  # type: ignore[arg-type]


if __name__ == "__main__":
    unittest.main()
