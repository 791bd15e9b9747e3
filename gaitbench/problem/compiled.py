"""Small CasADi functions compiled to C once per machine and loaded from a disk cache.

Compiling a whole step NLP does not pay (tens of seconds of gcc per grid size,
docs/decisions/0012-compiled-interval-blocks.md); compiling the few-thousand-instruction functions of one grid interval
does: they do not depend on N, so one compilation serves every grid, every worker process and every later run. The cache
is keyed by a hash of the generated C source and the compiler command, so a changed model or compiler never loads a
stale library.

Set ``GAITBENCH_CACHE`` to move the cache (default ``~/.cache/gaitbench``). Without a C compiler the function is
returned as it is, interpreted: the same values, only slower, and a warning says so once.
"""

from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
import warnings
from functools import cache
from pathlib import Path

import casadi as ca

COMPILE_FLAGS = ("-O1", "-shared", "-fPIC")
"""-O1: most of -O2's speed on straight-line generated code at a fraction of its compile time."""


def cache_directory() -> Path:
    return Path(os.environ.get("GAITBENCH_CACHE", Path.home() / ".cache" / "gaitbench")) / "compiled"


_LOADED: dict[tuple[str, bool], ca.Function] = {}
"""Libraries already loaded by this process, by the function's serialization: cheaper than generating its C."""


def compiled(function: ca.Function, differentiable: bool = False) -> ca.Function:
    """``function`` evaluated by compiled C, built on first use on this machine; interpreted if no compiler works.

    A compiled function has no derivatives of its own; ``differentiable`` compiles its reverse derivative into the
    same library, where CasADi finds it, so an expression graph that calls it can be differentiated once (as an
    NLP oracle is, for the gradient of the Lagrangian)."""
    key = (function.serialize(), differentiable)
    if key not in _LOADED:
        _LOADED[key] = _compile(function, differentiable)
    return _LOADED[key]


def _compile(function: ca.Function, differentiable: bool) -> ca.Function:
    compiler = _compiler()
    if compiler is None:
        _warn_once("no C compiler found (set CC): interval functions and derivatives are interpreted, several times "
                   "slower")
        return function
    name = function.name()
    with tempfile.TemporaryDirectory() as work:
        generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        generator.add(function)
        if differentiable:
            generator.add(function.reverse(1))
        source = Path(generator.generate(work + os.sep))
        text = source.read_bytes()
        digest = hashlib.sha256(text + " ".join((*compiler, *COMPILE_FLAGS)).encode()).hexdigest()[:20]
        library = cache_directory() / f"{name}-{digest}.so"
        if not library.exists():
            library.parent.mkdir(parents=True, exist_ok=True)
            partial = Path(work) / library.name
            command = [*compiler, *COMPILE_FLAGS, str(source), "-o", str(partial)]
            result = subprocess.run(command, capture_output=True, text=True)
            if result.returncode != 0:
                _warn_once(f"compiling {name} failed ({shlex.join(command)}): {result.stderr.strip()[:500]}; "
                           "it is interpreted")
                return function
            # Copy then rename within the cache: workers compiling the same function at once never see half a file.
            staged = library.with_suffix(f".{os.getpid()}.tmp")
            shutil.copyfile(partial, staged)
            os.replace(staged, library)
    return ca.external(name, str(library))


@cache
def _compiler() -> tuple[str, ...] | None:
    command = shlex.split(os.environ.get("CC", "cc"))
    if command and shutil.which(command[0]):
        return tuple(command)
    return None


@cache
def _warn_once(message: str) -> None:
    warnings.warn(f"gaitbench: {message}", RuntimeWarning, stacklevel=3)
