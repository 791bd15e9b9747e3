"""What a plugin hands to gaitbench: a named factory of one kind."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Registration:
    """One thing a plugin provides: a unique name within its kind, a one-line description and a factory.

    The factory is called only when the thing is used, so listing plugins stays cheap.
    """

    name: str
    description: str
    factory: Callable[..., Any]
