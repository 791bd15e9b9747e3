"""Physical parameters of the planar two-leg biped, validated once at construction."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

G_CONST = 9.81
"""Gravitational acceleration in m/s² (vertical; the thesis's slope factor is not used, docs/model.md §2)."""


class InvalidParameterError(ValueError):
    """A robot or experiment parameter is physically impossible; the message names the field."""


@dataclass(frozen=True)
class RobotParameters:
    """Masses, lengths and inertias of the biped.

    Each leg has length ``l`` with its centre of mass at distance ``a`` from the foot (``b = l - a`` from the
    hip); the hip is a point mass ``M``. ``I1``/``I2`` are the legs' inertias about their own centres of mass;
    left as ``None`` they default to the uniform-rod value ``m l² / 12`` (exact only for ``a = b``).
    """

    m1: float
    m2: float
    M: float
    l: float  # noqa: E741 - the thesis's symbol for leg length
    a: float
    I1: float | None = None
    I2: float | None = None
    g: float = G_CONST
    _inertias: tuple[float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("m1", "m2", "M", "l", "a", "g"):
            _require_finite(name, getattr(self, name))
        for name in ("I1", "I2"):
            value = getattr(self, name)
            if value is not None:
                _require_finite(name, value)
                if value < 0:
                    raise InvalidParameterError(
                        f"robot parameter {name} = {value}: an inertia cannot be negative"
                    )
        if self.m1 <= 0 or self.m2 <= 0:
            bad = "m1" if self.m1 <= 0 else "m2"
            raise InvalidParameterError(
                f"robot parameter {bad} = {getattr(self, bad)}: leg mass must be positive"
            )
        if self.M < 0:
            raise InvalidParameterError(f"robot parameter M = {self.M}: hip mass cannot be negative")
        if self.l <= 0:
            raise InvalidParameterError(f"robot parameter l = {self.l}: leg length must be positive")
        if not 0 < self.a < self.l:
            raise InvalidParameterError(
                f"robot parameter a = {self.a}: the leg's centre of mass must lie strictly between foot and hip "
                f"(0 < a < l = {self.l})"
            )
        if self.g <= 0:
            raise InvalidParameterError(f"robot parameter g = {self.g}: gravity must be positive")
        inertias = tuple(
            (m * self.l**2 / 12.0) if inertia is None else float(inertia)
            for m, inertia in ((self.m1, self.I1), (self.m2, self.I2))
        )
        object.__setattr__(self, "_inertias", inertias)

    @property
    def b(self) -> float:
        """Distance from the hip to a leg's centre of mass."""
        return self.l - self.a

    @property
    def inertia1(self) -> float:
        return self._inertias[0]

    @property
    def inertia2(self) -> float:
        return self._inertias[1]

    @property
    def total_mass(self) -> float:
        return self.M + self.m1 + self.m2

    def vector(self) -> np.ndarray:
        """Parameters in the order the symbolic model expects: m1, m2, M, l, a, I1, I2, g."""
        return np.array([self.m1, self.m2, self.M, self.l, self.a, self.inertia1, self.inertia2, self.g])

    def as_dict(self) -> dict[str, float]:
        return {
            "m1": self.m1,
            "m2": self.m2,
            "M": self.M,
            "l": self.l,
            "a": self.a,
            "b": self.b,
            "I1": self.inertia1,
            "I2": self.inertia2,
            "g": self.g,
        }


PARAMETER_NAMES = ("m1", "m2", "M", "l", "a", "I1", "I2", "g")


def _require_finite(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InvalidParameterError(f"robot parameter {name} = {value!r}: expected a finite number")
