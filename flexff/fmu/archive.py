"""extract_archive: the one way flexff unpacks an FMU or SSP archive, within a bound.

An archive from elsewhere may be a zip bomb (a few MB that inflate to GB) or name members
outside the folder it is unpacked into. Every member's name is checked (no absolute path, no
"..", no link) and its declared size counted against a bound before anything is written; while
writing, the bytes actually inflated are counted again, since a declared size may lie. On a
refusal nothing is left behind: the folder is removed (or emptied, when the caller gave it).

The bound is UNPACK_LIMIT bytes (1 GiB) in all, raised or lowered with the environment
variable FLEXFF_UNPACK_LIMIT (bytes, or a number with K, M or G for KiB, MiB, GiB).
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from flexff.fmu.errors import InputError

UNPACKED = "flexff-unpacked-"  # the prefix of the temporary folders FMUs are unpacked into
UNPACK_LIMIT = 1 << 30  # bytes an archive may unpack to, in all (1 GiB)
UNPACK_LIMIT_ENV = "FLEXFF_UNPACK_LIMIT"
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
_CHUNK = 1 << 20


def unpack_limit() -> int:
    """The bound in bytes: $FLEXFF_UNPACK_LIMIT if set, else UNPACK_LIMIT."""
    text = os.environ.get(UNPACK_LIMIT_ENV, "").strip()
    if not text:
        return UNPACK_LIMIT
    found = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([KMG]?)(?:i?B)?", text, flags=re.IGNORECASE)
    if found is None or float(found.group(1)) <= 0:
        raise InputError(f"${UNPACK_LIMIT_ENV} = {text!r}: expected a positive size in bytes, "
                         f"or with K, M or G (e.g. 4G)")
    return int(float(found.group(1)) * _UNITS[found.group(2).upper()])


def _refusal(archive: Path, member: str, why: str) -> InputError:
    return InputError(f"{archive}: member {member!r} {why}; the archive was not unpacked")


def _checked_members(archive: Path, zf: zipfile.ZipFile, limit: int) -> list[zipfile.ZipInfo]:
    """The archive's members, each name checked and their declared sizes within `limit`."""
    declared = 0
    for item in zf.infolist():
        name = PurePosixPath(item.filename.replace("\\", "/"))
        if (name.is_absolute() or ".." in name.parts or re.match(r"^[A-Za-z]:", item.filename)):
            raise _refusal(archive, item.filename, "points outside the folder it is unpacked "
                                                   "into")
        if stat.S_ISLNK(item.external_attr >> 16):
            raise _refusal(archive, item.filename, "is a symbolic link")
        declared += item.file_size
        if declared > limit:
            raise _refusal(archive, item.filename, f"takes the declared unpacked size past "
                                                   f"{limit} bytes (${UNPACK_LIMIT_ENV} "
                                                   f"raises the bound)")
    return zf.infolist()


def check_archive(path: str | Path) -> None:
    """Check an archive's member names and declared sizes (for an importer that unpacks it
    itself, such as libcosim); InputError naming the member at fault."""
    path = Path(path)
    with zipfile.ZipFile(path) as zf:
        _checked_members(path, zf, unpack_limit())


def extract_archive(path: str | Path, folder: str | Path | None = None) -> Path:
    """Unpack the zip archive `path` into `folder` (new or empty; default a new temporary
    folder) within the bound, and return the folder. InputError naming the archive and the
    member refused (module doc) or damaged; zipfile.BadZipFile for a file that is no zip."""
    path = Path(path)
    limit = unpack_limit()
    target = Path(tempfile.mkdtemp(prefix=UNPACKED) if folder is None else folder)
    existed = folder is not None and target.is_dir()
    if existed and any(target.iterdir()):
        raise ValueError(f"{target} is not empty: an archive is unpacked into a folder of its own")
    try:
        target.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(path) as zf:
            members = _checked_members(path, zf, limit)
            written = 0
            for item in members:
                parts = PurePosixPath(item.filename.replace("\\", "/")).parts
                destination = target.joinpath(*parts)
                if item.is_dir():
                    destination.mkdir(parents=True, exist_ok=True)
                    continue
                destination.parent.mkdir(parents=True, exist_ok=True)
                try:
                    source = zf.open(item)
                except (zipfile.BadZipFile, OSError) as error:  # OSError: a member's header
                    # offset before the file's start (a byte cut from the archive's head)
                    raise _refusal(path, item.filename, f"is damaged ({error}: its header is "
                                   f"not where the archive's directory says)") from None
                try:
                    with source, open(destination, "wb") as sink:
                        # zipfile stops at the declared size (a member inflating past it
                        # fails its CRC); counting here keeps the bound independent of that
                        while chunk := source.read(_CHUNK):
                            written += len(chunk)
                            if written > limit:
                                raise _refusal(path, item.filename, f"unpacks past {limit} "
                                               f"bytes (${UNPACK_LIMIT_ENV} raises the bound)")
                            sink.write(chunk)
                except (zipfile.BadZipFile, zlib.error, EOFError) as error:
                    raise _refusal(path, item.filename, f"is damaged ({error})") from None
    except BaseException:
        if existed:
            for child in target.iterdir():
                shutil.rmtree(child) if child.is_dir() else child.unlink()
        else:
            shutil.rmtree(target, ignore_errors=True)
        raise
    return target
