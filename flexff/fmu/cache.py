"""Content-addressed cache of built files, so that rebuilding an unchanged FMU is a copy.

The key is a sha256 over everything that goes into a build (sources, XML, flags, compiler);
files live in `$FLEXFF_CACHE`, or `~/.cache/flexff/fmu` when it is unset.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path


def cache_dir() -> Path:
    """The cache folder (created on demand)."""
    folder = Path(os.environ.get("FLEXFF_CACHE") or Path.home() / ".cache" / "flexff" / "fmu")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def file_sha256(path: Path) -> str:
    """The sha256 of a file's bytes, as hex."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def digest(parts: Mapping[str, str | bytes]) -> str:
    """sha256 hex digest of named parts, independent of their order, unambiguous in framing."""
    h = hashlib.sha256()
    for name in sorted(parts):
        part = parts[name]
        data = part.encode() if isinstance(part, str) else part
        for chunk in (name.encode(), data):
            h.update(len(chunk).to_bytes(8, "little"))
            h.update(chunk)
    return h.hexdigest()


def cached_path(key: str, suffix: str) -> Path:
    """Where the file for `key` lives in the cache (it may not exist yet)."""
    return cache_dir() / f"{key}{suffix}"


def store(key: str, suffix: str, file: Path) -> Path:
    """Copy `file` into the cache atomically (concurrent builds never see half a file)."""
    target = cached_path(key, suffix)
    fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".tmp")
    os.close(fd)
    shutil.copy(file, tmp)  # keeps the mode bits (executables stay executable)
    os.replace(tmp, target)
    return target
