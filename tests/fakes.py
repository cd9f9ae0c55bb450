"""Small test doubles shared by the test modules (import: ``from fakes import ...``)."""

from __future__ import annotations


class FakeClock:
    """A manual clock: tests set ``t`` (seconds); the emulator calls it."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t
