"""Environment identities: the name, settings hash and parameters every task names and every
worker declares, exactly as Rust's ``EnvironmentSpec`` (``shared/src/spec.rs``)."""

from __future__ import annotations

import json
from collections.abc import Sequence

from . import _wire

#: The FNV-1a 64 offset basis: the hash of no bytes.
FNV_OFFSET = 0xCBF29CE484222325
_FNV_PRIME = 0x100000001B3
_MASK = (1 << 64) - 1
_NAME_CHARS = frozenset(b"abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_.")
_UNNAMED = "unnamed"


def fnv1a(data: bytes, start: int = FNV_OFFSET) -> int:
    """FNV-1a (64 bit) of ``data``, continued from ``start`` (Rust: ``acps_shared::fnv1a``)."""
    value = start
    for byte in data:
        value = ((value ^ byte) * _FNV_PRIME) & _MASK
    return value


class Environment:
    """The identity of the environment a worker serves.

    ``settings`` is either the settings text, hashed with FNV-1a 64 over its UTF-8 bytes exactly
    as Rust's ``EnvironmentSpec::from_text`` does, or the hash itself as an int (for example one
    read from a policy file). Two environments with equal identities must perform the same
    rollouts: anything that changes them must change the identity.

    >>> str(Environment("reach-2d", settings="dt=0.01", parameters=(1, 0, 0)))
    'reach-2d [1, 0, 0] (settings 30178b206d634ad5)'
    """

    __slots__ = ("name", "parameters", "settings", "text")

    name: str
    settings: int
    parameters: tuple[int, int, int]
    text: str | None
    """The settings text, when the settings were given as text (not only their hash): a
    refusal shows it beside the hash."""

    def __init__(
        self,
        name: str,
        settings: str | int = "",
        parameters: Sequence[int] = (0, 0, 0),
    ) -> None:
        """The identity ``name`` with ``settings`` (text or hash) and three ``parameters``."""
        raw = name.encode("ascii", errors="replace")
        if not (1 <= len(raw) <= _wire.MAX_NAME) or not all(b in _NAME_CHARS for b in raw):
            raise ValueError(
                f"environment name {name!r} must be 1 to {_wire.MAX_NAME} characters of "
                "ASCII letters, digits, '-', '_' and '.'"
            )
        text = None
        if isinstance(settings, str):
            hashed = fnv1a(settings.encode("utf-8"))
            text = settings
        elif isinstance(settings, int) and not isinstance(settings, bool):
            if not 0 <= settings <= _MASK:
                raise ValueError(f"environment settings hash {settings} is not a u64")
            hashed = settings
        else:
            raise TypeError(f"environment settings must be text or an int hash, got {settings!r}")
        params = tuple(parameters)
        if len(params) != 3 or not all(
            isinstance(p, int) and not isinstance(p, bool) and 0 <= p <= _MASK for p in params
        ):
            raise ValueError(f"environment parameters must be three u64, got {parameters!r}")
        self.name = name
        self.settings = hashed
        self.parameters = (params[0], params[1], params[2])
        self.text = text

    @classmethod
    def unnamed(cls) -> Environment:
        """The identity of an environment nobody named (it matches only problems naming none)."""
        return cls(_UNNAMED, "", (0, 0, 0))

    def is_unnamed(self) -> bool:
        """Whether this is :meth:`unnamed`."""
        return self == Environment.unnamed()

    @classmethod
    def from_wire(cls, wire: _wire.WireEnvironment) -> Environment | None:
        """The identity a wire environment carries, ``None`` when it is no valid one."""
        raw = bytes(wire.name)
        length = raw.find(b"\0")
        length = len(raw) if length < 0 else length
        if any(raw[length:]):
            return None
        try:
            return cls(raw[:length].decode("ascii"), int(wire.settings), tuple(wire.parameters))
        except (ValueError, UnicodeDecodeError):
            return None

    def to_wire(self) -> _wire.WireEnvironment:
        """The identity as it crosses the wire."""
        wire = _wire.WireEnvironment()
        raw = self.name.encode("ascii")
        ctypes_name = wire.name
        for i, byte in enumerate(raw):
            ctypes_name[i] = byte
        wire.settings = self.settings
        wire.parameters[:] = self.parameters
        return wire

    def shown(self) -> str:
        """As :meth:`__str__`, followed by the settings text when it is known, as a message
        carries it (Rust: ``serves_shown``)."""
        return f"{self}{shown_settings_text(*self.settings_text_to_wire())}"

    def settings_text_to_wire(self) -> tuple[int, bytes]:
        """The settings text as a message carries it: its length in bytes and its first
        ``MAX_SETTINGS_TEXT`` bytes, cut at a character boundary ((0, b"") when unknown)."""
        if self.text is None:
            return 0, b""
        raw = self.text.encode("utf-8")
        return len(raw), raw[: _wire.MAX_SETTINGS_TEXT].decode("utf-8", "ignore").encode("utf-8")

    def __eq__(self, other: object) -> bool:
        """Equal identities: the same name, settings hash and parameters."""
        if not isinstance(other, Environment):
            return NotImplemented
        return (self.name, self.settings, self.parameters) == (
            other.name,
            other.settings,
            other.parameters,
        )

    def __hash__(self) -> int:
        """A hash consistent with equality."""
        return hash((self.name, self.settings, self.parameters))

    def __str__(self) -> str:
        """As Rust displays it: ``name [a, b, c] (settings 0123456789abcdef)``."""
        if self.is_unnamed():
            return "no named environment"
        a, b, c = self.parameters
        return f"{self.name} [{a}, {b}, {c}] (settings {self.settings:016x})"

    def __repr__(self) -> str:
        """``Environment('name', settings=0x..., parameters=(a, b, c))``."""
        return (
            f"Environment({self.name!r}, settings=0x{self.settings:016x}, "
            f"parameters={self.parameters!r})"
        )


def shown_settings_text(length: int, carried: bytes) -> str:
    """A settings text as a message carried it, for people (Rust: ``shown_settings_text``):
    `` = "TEXT"``, or `` = "START..." (N bytes)`` when it was longer than the message holds;
    empty when the sender knew none."""
    if length == 0:
        return ""
    end = carried.find(b"\0")
    carried = carried if end < 0 else carried[:end]
    text = json.dumps(carried[:length].decode("utf-8", "replace"), ensure_ascii=False)
    return f" = {text}... ({length} bytes)" if length > len(carried) else f" = {text}"
