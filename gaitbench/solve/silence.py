"""Silencing solver libraries that print whatever their verbosity options say.

Several solvers write from C straight to file descriptor 1 (qpOASES' banner, HiGHS', OSQP's polishing notes,
IPOPT's option complaints), which Python's ``sys.stdout`` redirection cannot catch; ``print_level=0`` promises
silence, so solver plugins wrap those calls in :func:`quiet_stdout` (and :func:`quiet_stderr` for libraries that
warn on standard error, such as Uno's BQPD).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
from collections.abc import Iterator

_C_RUNTIME = ctypes.CDLL(None) if os.name == "posix" else None
"""The C library, to flush what C code buffered for standard output before it is restored."""


@contextlib.contextmanager
def quiet_stdout(active: bool = True) -> Iterator[None]:
    """Discard standard output, both Python's and file descriptor 1 (process-wide while it is active)."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        if _C_RUNTIME is not None:
            _C_RUNTIME.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


@contextlib.contextmanager
def quiet_stderr(active: bool = True) -> Iterator[None]:
    """Discard what is written to file descriptor 2 while active. Python's own ``sys.stderr`` is flushed first and
    still goes to descriptor 2 afterwards, so a traceback printed outside the block is unaffected."""
    if not active:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
