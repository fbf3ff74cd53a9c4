"""build_fmu: System -> FMI 2.0 co-simulation FMU (generated C + generic wrapper, compiled, zipped).

The FMU holds modelDescription.xml, binaries/<platform>/<id>.so and sources/ (wrapper, generated
code, config.h and the FMI headers, listed in the XML's SourceFiles) so it can be rebuilt
elsewhere with `cc -shared -fPIC -Isources sources/*.c -lm`. Builds are cached by a hash of all
their inputs; the GUID is derived from the same hash, so equal inputs give a bit-equal FMU.
"""

from __future__ import annotations

import shutil
import tempfile
import uuid
import zipfile
from pathlib import Path

import fmpy

from fmu import cache
from fmu.codegen import generate_config_h, generate_model_c
from fmu.compile import CFLAGS, compiler_version, fmi_headers, run_compiler
from fmu.layout import make_layout, model_identifier
from fmu.model_description import model_description_xml
from fmu.system import System

WRAPPER = Path(__file__).parent / "c" / "fmi2_cosim.c"
SOURCE_FILES = ["fmi2_cosim.c", "model.c"]
GUID_PLACEHOLDER = "{00000000-0000-0000-0000-000000000000}"
GUID_FILES = ("modelDescription.xml", "sources/config.h")
ZIP_DATE = (2020, 1, 1, 0, 0, 0)  # fixed timestamps keep the archive reproducible


def _files(system: System, guid: str) -> dict[str, str]:
    """Every text file of the FMU, by archive path."""
    identifier = model_identifier(system)
    layout = make_layout(system)
    sources = {
        "fmi2_cosim.c": WRAPPER.read_text(),
        "config.h": generate_config_h(system, layout, identifier, guid),
        **generate_model_c(system, identifier),
        **fmi_headers(),
    }
    files = {f"sources/{name}": text for name, text in sources.items()}
    files["modelDescription.xml"] = model_description_xml(system, layout, identifier, guid,
                                                          SOURCE_FILES)
    return files


def _key(files: dict[str, str]) -> str:
    parts: dict[str, str | bytes] = dict(files)
    parts["cflags"] = " ".join(CFLAGS)
    parts["compiler"] = compiler_version()
    return cache.digest(parts)


def fmu_key(system: System) -> str:
    """sha256 of everything that goes into the build of `system` (its GUID derives from it)."""
    return _key(_files(system, GUID_PLACEHOLDER))


def _with_guid(files: dict[str, str], key: str) -> dict[str, str]:
    """The files with the placeholder replaced by the GUID derived from the key."""
    guid = "{" + str(uuid.UUID(key[:32])) + "}"
    return {name: text.replace(GUID_PLACEHOLDER, guid) if name in GUID_FILES else text
            for name, text in files.items()}


def _write_fmu(files: dict[str, str], identifier: str, target: Path) -> None:
    """Compile the sources and zip the FMU into `target`."""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, text in files.items():
            if name.startswith("sources/"):
                (src / name.removeprefix("sources/")).write_text(text)
        library = Path(tmp) / f"{identifier}{fmpy.sharedLibraryExtension}"
        run_compiler([src / name for name in SOURCE_FILES], library, [src])
        with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                zf.writestr(zipfile.ZipInfo(name, ZIP_DATE), files[name], zipfile.ZIP_DEFLATED)
            info = zipfile.ZipInfo(f"binaries/{fmpy.platform}/{library.name}", ZIP_DATE)
            info.external_attr = 0o755 << 16
            zf.writestr(info, library.read_bytes(), zipfile.ZIP_DEFLATED)


def build_fmu(system: System, path: str | Path) -> Path:
    """Build (or fetch from the cache) the FMU of `system` and copy it to `path`."""
    path = Path(path)
    files = _files(system, GUID_PLACEHOLDER)
    key = _key(files)
    cached = cache.cached_path(key, ".fmu")
    if not cached.exists():
        with tempfile.TemporaryDirectory() as tmp:
            fresh = Path(tmp) / "model.fmu"
            _write_fmu(_with_guid(files, key), model_identifier(system), fresh)
            cache.store(key, ".fmu", fresh)
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cached, path)
    return path
