"""Where a pack is read from: unpacked once into a cache directory keyed by its content, then read as a store.

``ResultStore.open`` hands a pack (:func:`gaitbench.run.pack_format.is_pack`) to :func:`unpacked`, which returns the
store directory inside the cache, its files read-only; every command that reads a store therefore reads a pack.

The cache is ``packs`` in gaitbench's cache directory: ``$GAITBENCH_CACHE`` where it is set (as for the compiled
functions, :mod:`gaitbench.problem.compiled`), else ``$XDG_CACHE_HOME/gaitbench``, else ``~/.cache/gaitbench``; where
that cannot be written, ``gaitbench-packs-<uid>`` in the temporary directory. Each pack lives in
``<sha256 of its bytes, first 32 hex digits>/<store name>``: the same pack is unpacked once wherever it lies and
whatever it is called, and a changed pack gets a directory of its own. Unpacking goes to a staging directory that
is renamed into place when it is whole, so a killed unpack leaves nothing that is read, and two processes
unpacking the same pack at once both end up reading the one that was renamed first. Deleting the cache costs
only the next unpack.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
import tempfile
from pathlib import Path

from gaitbench.run.pack_format import PackError, extract, read_only

_KEY_DIGITS = 32
_CHUNK = 1 << 20


def cache_root() -> Path:
    """The directory packs are unpacked into (made if needed): see the module docstring."""
    configured = os.environ.get("GAITBENCH_CACHE")
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    root = (Path(configured) if configured else Path(xdg) / "gaitbench") / "packs"
    try:
        root.mkdir(parents=True, exist_ok=True)
        if os.access(root, os.W_OK):
            return root
    except OSError:
        pass
    return _private_temp()


def _private_temp() -> Path:
    """``gaitbench-packs-<uid>`` in the temporary directory, when it is this user's alone (0700, owned by them);
    otherwise a new private directory: another user must not be able to plant a store for this one to read."""
    root = Path(tempfile.gettempdir()) / f"gaitbench-packs-{os.getuid()}"
    try:
        root.mkdir(mode=0o700, exist_ok=True)
        status = root.lstat()
        if stat.S_ISDIR(status.st_mode) and status.st_uid == os.getuid() and stat.S_IMODE(status.st_mode) == 0o700:
            return root
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix="gaitbench-packs-"))


def content_key(pack: Path) -> str:
    """The first digits of the SHA-256 of the pack's bytes: the name of its directory in the cache."""
    digest = hashlib.sha256()
    try:
        with open(pack, "rb") as file:
            while chunk := file.read(_CHUNK):
                digest.update(chunk)
    except OSError as error:
        raise PackError(f"{pack}: cannot read the results pack ({error.strerror or error})") from None
    return digest.hexdigest()[:_KEY_DIGITS]


def unpacked(pack: str | Path) -> Path:
    """The store directory of ``pack`` in the cache, unpacked now if it is not there yet; its files read-only.
    :class:`PackError` (one line naming the pack) when it cannot be read or is no gaitbench pack."""
    pack = Path(pack)
    if not pack.is_file():
        raise PackError(f"{pack}: no results pack here; name a .tar.xz written by `gaitbench runs pack`, or a store "
                        "directory")
    root = cache_root()
    home = root / content_key(pack)
    if not _store_in(home):
        staging = Path(tempfile.mkdtemp(prefix=f".{home.name}-", dir=root))
        try:
            manifest = extract(pack, staging / "store")
            name = _store_name(manifest)
            (staging / "store").rename(staging / name)
            read_only(staging)
            try:
                staging.rename(home)
            except OSError:  # another process renamed its copy first: read that one
                if not _store_in(home):
                    raise
        except OSError as error:
            raise PackError(f"{pack}: cannot unpack it into {root} ({error.strerror or error})") from None
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    found = _store_in(home)
    if found is None:
        raise PackError(f"{pack}: its unpacked copy {home} is not a store; delete that directory and try again")
    return found


def _store_name(manifest: dict) -> str:
    """The directory name the store keeps in the cache (the store's own, where it is a plain name)."""
    name = manifest.get("store")
    return name if isinstance(name, str) and name not in ("", ".", "..") and "/" not in name else "store"


def _store_in(home: Path) -> Path | None:
    """The one store directory in a pack's cache directory, or None."""
    try:
        entries = [entry for entry in home.iterdir() if entry.is_dir() and not entry.is_symlink()]
    except OSError:
        return None
    return entries[0] if len(entries) == 1 and (entries[0] / "results.sqlite").is_file() else None
