"""The packed results store: what a pack holds, how it is recognised, and how it is read back safely.

A pack is one ``.tar.xz`` file (:mod:`gaitbench.run.store_pack` writes it) holding one store under one top
directory named after it::

    <name>/gaitbench-pack.json     {"gaitbench": "pack", "format": 1, "trajectories": "all" | "report", ...}
    <name>/results.sqlite          the database, one consistent file (no WAL beside it, no claims)
    <name>/cases/<key>/...         each case's files: the marker, walk.json, track.json, and the trajectories
                                   (``*.npz``): every one (``all``), or those the store's report draws (``report``)

Reading one never trusts its member names: only regular files and directories under the one top directory, with
plain relative names, are written, and each one by name (never ``extractall``), so a member such as
``../../.bashrc``, an absolute path, a link or a device is refused with a :class:`PackError` naming the pack.
"""

from __future__ import annotations

import json
import lzma
import os
import posixpath
import tarfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from gaitbench.run.store_schema import StoreError

PACK_SUFFIX = ".tar.xz"
MANIFEST = "gaitbench-pack.json"
PACK_FORMAT = 1
TRAJECTORY_SUFFIX = ".npz"
TRAJECTORY_MODES = ("all", "report")
"""``all``: every trajectory file of the store; ``report``: only those its report draws (the chosen gaits and
the tracking series), so that a sweep of hundreds of walks packs into a few MB."""

_XZ_MAGIC = b"\xfd7zXZ\x00"


class PackError(StoreError):
    """A pack that cannot be read (not an xz tar, not a gaitbench pack, a member that would land outside it) or
    written to; one line naming the file."""


def is_pack(path: str | Path) -> bool:
    """Whether ``path`` names a pack rather than a store directory: a name ending in ``.tar.xz``, or a file that
    is xz-compressed."""
    path = Path(path)
    if path.name.endswith(PACK_SUFFIX):
        return True
    try:
        with open(path, "rb") as file:
            return path.is_file() and file.read(len(_XZ_MAGIC)) == _XZ_MAGIC
    except OSError:
        return False


def refusal(path: str | Path) -> str:
    """Why a command that writes a store cannot write ``path``, and what to do instead."""
    return (f"{path}: a packed results store, which is read-only; unpack it with `gaitbench runs unpack {path} DIR` "
            "and use DIR, or run into a store directory")


def extract(pack: Path, destination: Path) -> dict[str, Any]:
    """Write the store in ``pack`` into ``destination`` (made if needed; a file it holds already is refused), with
    the permissions of the umask; returns the pack's manifest. :class:`PackError` (one line naming the pack)
    for a file that is not a readable xz tar, not a gaitbench pack, or has a member that is not a plain file or
    directory under the pack's top directory; what was written by then stays for the caller to remove."""
    manifest = None
    try:
        with tarfile.open(pack, mode="r:xz") as tar:
            top = None
            for member, relative in _members(tar, pack):
                top = top or member.name.split("/", 1)[0]
                if member.name.split("/", 1)[0] != top:
                    raise PackError(f"{pack}: not a gaitbench results pack (more than one top directory: {top!r} "
                                    f"and {member.name.split('/', 1)[0]!r})")
                target = destination.joinpath(*relative.split("/")) if relative else destination
                if member.isdir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                source = tar.extractfile(member)
                content = source.read() if source is not None else b""
                if relative == MANIFEST:
                    manifest = _manifest(content, pack)
                with open(target, "xb") as out:  # "x": a member named twice is refused, never overwrites
                    out.write(content)
    except (tarfile.TarError, lzma.LZMAError, EOFError) as error:
        raise PackError(f"{pack}: not a readable results pack ({type(error).__name__}: {error}); "
                        f"expected a .tar.xz written by `gaitbench runs pack`") from None
    except FileExistsError as error:
        raise PackError(f"{pack}: not a gaitbench results pack (it holds {error.filename} twice)") from None
    except OSError as error:
        raise PackError(f"{pack}: cannot unpack it into {destination} ({error.strerror or error})") from None
    if manifest is None:
        raise PackError(f"{pack}: not a gaitbench results pack (no {MANIFEST} in it); expected a .tar.xz written by "
                        "`gaitbench runs pack`")
    if not (destination / "results.sqlite").is_file():
        raise PackError(f"{pack}: a gaitbench pack without its results.sqlite; pack the store again")
    return manifest


def _members(tar: tarfile.TarFile, pack: Path) -> Iterator[tuple[tarfile.TarInfo, str]]:
    """Each member with its name below the top directory; :class:`PackError` for one that is not a plain file or
    directory with a plain relative name."""
    for member in tar:
        name = member.name
        parts = name.split("/")
        if (not (member.isfile() or member.isdir()) or name.startswith("/") or "\\" in name or ".." in parts
                or posixpath.normpath(name) != name.rstrip("/") or name in ("", ".")
                or (member.isfile() and len(parts) < 2)):
            kind = "file" if member.isfile() else "directory" if member.isdir() else "link or special file"
            raise PackError(f"{pack}: refused member {name!r} ({kind}): a pack holds only plain files and "
                            "directories under its top directory; it was not written by `gaitbench runs pack`")
        yield member, "/".join(parts[1:]).rstrip("/")


def _manifest(content: bytes, pack: Path) -> dict[str, Any]:
    try:
        manifest = json.loads(content)
    except (UnicodeDecodeError, json.JSONDecodeError):
        manifest = None
    if not isinstance(manifest, dict) or manifest.get("gaitbench") != "pack":
        raise PackError(f"{pack}: not a gaitbench results pack (its {MANIFEST} is not one)")
    if manifest.get("format") != PACK_FORMAT:
        raise PackError(f"{pack}: pack format {manifest.get('format')!r} is unknown to this gaitbench, which reads "
                        f"format {PACK_FORMAT}; read it with the gaitbench that wrote it")
    return manifest


def read_manifest(store_dir: Path) -> dict[str, Any] | None:
    """The manifest of a store that came out of a pack, or None for any other store."""
    try:
        manifest = json.loads((store_dir / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) and manifest.get("gaitbench") == "pack" else None


def left_out(store_dir: Path, walk_path: str) -> str | None:
    """Why the stored walk ``walk_path`` (relative to ``store_dir``) cannot be drawn or verified, when the pack the
    store came from left its trajectories out; None when they are there or the store is no such pack."""
    manifest = read_manifest(store_dir)
    if manifest is None or manifest.get("trajectories") == "all":
        return None
    walk_file = store_dir / walk_path
    try:
        name = json.loads(walk_file.read_text(encoding="utf-8")).get("trajectories")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(name, str) or (walk_file.parent / name).is_file():
        return None
    return (f"{walk_path}: its trajectories are not in this pack of {manifest.get('store', 'the store')}, which "
            f"holds only the ones its report draws (--trajectories {manifest.get('trajectories')}); read the whole "
            "store, or a pack of it made with `gaitbench runs pack STORE OUT --trajectories all` "
            "(docs/results.md, \"Packed stores\")")


def read_only(directory: Path) -> None:
    """Make every file under ``directory`` read-only (its directories stay removable by their owner)."""
    for root, _, files in os.walk(directory):
        for name in files:
            os.chmod(os.path.join(root, name), 0o444)
