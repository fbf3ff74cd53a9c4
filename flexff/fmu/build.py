"""build_fmu: System -> FMI 2.0 or 3.0 co-simulation FMU (generated C + generic wrapper,
compiled, zipped).

The FMU holds modelDescription.xml, binaries/<platform>/ and sources/ (wrapper, generated code,
config.h, the FMI headers; listed in the XML's SourceFiles for FMI 2.0, in buildDescription.xml
for 3.0, whose library adds c/fmi3Functions.c over the same core: bit for bit its 2.0 twin), so
it can be rebuilt with `cc -shared -fPIC -Isources sources/*.c -lm -ldl -lpthread`. A network
is in sources/ as generated C (runtime "c", the default); with "onnxruntime" the graph goes to
resources/ and onnxruntime's library beside the FMU's own, for the host alone. The library is
built for the host unless `platforms` (fmu.platforms) names others, or none (sources alone).
Builds are cached by a hash of all their inputs; the GUID (FMI 3.0: instantiation token) is
derived from it, so equal inputs give a bit-equal FMU. `$FLEXFF_SANITIZE` builds the host's
library with sanitizers (fmu.compile.sanitizer_flags), under its own key.
"""

from __future__ import annotations

import shutil
import tempfile
import uuid
import zipfile
from collections.abc import Sequence
from pathlib import Path

from flexff.fmu import cache
from flexff.fmu.codegen import NET_MODEL_FILE, NET_TABLE_FILE, generate_config_h, generate_model_c
from flexff.fmu.compile import CFLAGS, compiler_version, fmi_headers, run_compiler, sanitizer_flags
from flexff.fmu.errors import InputError
from flexff.fmu.fmi_version import check_fmi_version
from flexff.fmu.layout import make_layout, model_identifier
from flexff.fmu.model_description import model_description_xml
from flexff.fmu.model_description3 import build_description_xml, model_description3_xml
from flexff.fmu.network import Network, runtime_library
from flexff.fmu.network_c import FMU_PREFIX, fmu_network_sources
from flexff.fmu.platforms import PLATFORMS, host, resolve
from flexff.fmu.system import System

C_DIR = Path(__file__).parent / "c"
# the generic wrapper (see c/wrapper.h), compiled with the generated model.c of each FMU
WRAPPER_C_FILES = ("fmi2Functions.c", "wrapper.c", "rng.c")
WRAPPER_HEADERS = ("wrapper.h", "rng.h")
FMI3_C_FILES = ("fmi3Functions.c",)  # an FMI 3.0 FMU's API, over the FMI 2.0 core
FMI3_HEADERS = ("fmi2_core.h",)
NETWORK_C_FILES = ("wrapper_network.c", "net_times.c")
NETWORK_HEADERS = ("onnx_network.h", "net_times.h")
# each runtime's C files and headers (the generated flexff_net.c/h besides, for "c")
RUNTIME_C_FILES = {"c": ("c_network.c",), "onnxruntime": ("onnx_network.c",)}
RUNTIME_HEADERS = {"c": ("net_kernels.h",),
                   "onnxruntime": ("onnxruntime_c_api.h", "onnxruntime_c_api.LICENSE.txt")}
TASK_C_FILES = ("wrapper_task.c",)  # a network in its own task
GUID_PLACEHOLDER = "{00000000-0000-0000-0000-000000000000}"
GUID_FILES = ("modelDescription.xml", "sources/config.h")
ZIP_DATE = (2020, 1, 1, 0, 0, 0)  # fixed timestamps keep the archive reproducible


def platform_folder(fmi_version: int, platform: str | None = None) -> str:
    """The binaries/ folder of `platform` (default: the host's) as FMI `fmi_version` names it."""
    chosen = PLATFORMS[platform or host()]
    return chosen.name if fmi_version == 2 else chosen.fmi3


def _source_files(system: System, fmi_version: int) -> list[str]:
    """The C files compiled into the FMU's library."""
    net = system.network
    api = FMI3_C_FILES if fmi_version == 3 else ()
    if net is None:
        return [*WRAPPER_C_FILES, *api, "model.c"]
    return [*WRAPPER_C_FILES, *api, "model.c", *NETWORK_C_FILES, *RUNTIME_C_FILES[net.runtime],
            *([f"{FMU_PREFIX}.c"] if net.runtime == "c" else []),
            *(TASK_C_FILES if net.task else ())]


def _files(system: System, guid: str, fmi_version: int) -> dict[str, str | bytes]:
    """Every file of the FMU but its compiled library, by archive path."""
    identifier = model_identifier(system)
    layout = make_layout(system)
    net = system.network
    generic = (*WRAPPER_C_FILES, *WRAPPER_HEADERS,
               *((*FMI3_C_FILES, *FMI3_HEADERS) if fmi_version == 3 else ()),
               *((*NETWORK_C_FILES, *NETWORK_HEADERS, *RUNTIME_C_FILES[net.runtime],
                  *RUNTIME_HEADERS[net.runtime]) if net else ()),
               *(TASK_C_FILES if net and net.task else ()))
    sources = {
        **{name: (C_DIR / name).read_text() for name in generic},
        "config.h": generate_config_h(system, layout, identifier, guid, fmi_version),
        **generate_model_c(system, identifier),
        **(fmu_network_sources(net.model) if net and net.runtime == "c" else {}),
        **fmi_headers(fmi_version),
    }
    files: dict[str, str | bytes] = {f"sources/{name}": text for name, text in sources.items()}
    if fmi_version == 3:
        files["modelDescription.xml"] = model_description3_xml(system, layout, identifier, guid)
        files["sources/buildDescription.xml"] = build_description_xml(
            identifier, _source_files(system, fmi_version))
    else:
        files["modelDescription.xml"] = model_description_xml(
            system, layout, identifier, guid, _source_files(system, fmi_version))
    if system.network:
        files.update(_network_files(system.network, [u.name for u in system.inputs],
                                    platform_folder(fmi_version)))
    return files


def _network_files(net: Network, input_names: list[str], platform: str) -> dict[str, bytes]:
    """The precomputation table; for onnxruntime the graph and the library too."""
    files: dict[str, bytes] = {}
    if net.table is not None:
        if net.table.shape[1] != 1 + len(input_names):
            raise ValueError(f"the precomputation table needs {1 + len(input_names)} columns "
                             f"(time, {', '.join(input_names)}), got {net.table.shape[1]}")
        lines = [",".join(["time", *input_names])]
        lines += [",".join(map(repr, map(float, row))) for row in net.table]
        files[f"resources/{NET_TABLE_FILE}"] = ("\n".join(lines) + "\n").encode()
    if net.runtime == "onnxruntime":
        library = runtime_library()
        files[f"resources/{NET_MODEL_FILE}"] = net.model.read_bytes()
        files[f"binaries/{platform}/{library.name}"] = library.read_bytes()
    return files


def _key(files: dict[str, str | bytes], platforms: tuple[str, ...]) -> str:
    parts = {name: (f"{len(data)} bytes" if name.startswith("binaries/") else data)
             for name, data in files.items()}  # the runtime library is named by its version
    parts["cflags"] = " ".join(CFLAGS + sanitizer_flags())
    parts["compiler"] = compiler_version()
    if platforms != (host(),):  # the host's alone: the key as before platforms existed
        parts["platforms"] = " ".join(platforms)
        for name in platforms:
            parts[f"compiler {name}"] = compiler_version(PLATFORMS[name].compiler())
            parts[f"libraries {name}"] = " ".join(PLATFORMS[name].libraries)
    return cache.digest(parts)


def _check_platforms(system: System, platforms: tuple[str, ...]) -> None:
    """InputError for a platform the system's network cannot run on."""
    net = system.network
    if net is not None and net.runtime == "onnxruntime" and platforms != (host(),):
        raise InputError(f"a network in onnxruntime runs on {host()} alone (the library "
                         f"bundled is this machine's): build it with --runtime c for other "
                         f"platforms or for sources alone")


def fmu_key(system: System, fmi_version: int = 2, platforms: Sequence[str] | None = None
            ) -> str:
    """sha256 of everything that goes into the build of `system` as an FMI `fmi_version` FMU
    for `platforms` (as build_fmu takes them); its GUID derives from it."""
    return _key(_files(system, GUID_PLACEHOLDER, check_fmi_version(fmi_version)),
                resolve(platforms))


def _with_guid(files: dict[str, str | bytes], key: str) -> dict[str, str | bytes]:
    """The files with the placeholder replaced by the GUID derived from the key."""
    guid = "{" + str(uuid.UUID(key[:32])) + "}"
    return {name: text.replace(GUID_PLACEHOLDER, guid)
            if name in GUID_FILES and isinstance(text, str) else text
            for name, text in files.items()}


def _write_fmu(files: dict[str, str | bytes], sources: list[str], identifier: str,
               platforms: tuple[str, ...], fmi_version: int, target: Path) -> None:
    """Compile the sources for each platform and zip the FMU into `target`."""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, text in files.items():
            if name.startswith("sources/"):
                target_file = src / name.removeprefix("sources/")
                if isinstance(text, str):
                    target_file.write_text(text)
                else:
                    target_file.write_bytes(text)
        files = dict(files)
        for name in platforms:
            platform = PLATFORMS[name]
            library = Path(tmp) / name / f"{identifier}{platform.extension}"
            library.parent.mkdir()
            sanitizers = sanitizer_flags() if name == host() else ()  # the host runs those
            run_compiler([src / source for source in sources], library, [src],
                         extra_flags=("-shared", *sanitizers), libraries=platform.libraries,
                         command=platform.compiler())
            files[f"binaries/{platform_folder(fmi_version, name)}/{library.name}"] = \
                library.read_bytes()
        with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, ZIP_DATE)
                if name.startswith("binaries/"):
                    info.external_attr = 0o755 << 16
                zf.writestr(info, files[name], zipfile.ZIP_DEFLATED)


def build_fmu(system: System, path: str | Path, fmi_version: int = 2,
              platforms: Sequence[str] | None = None) -> Path:
    """Build (or fetch from the cache) the FMI `fmi_version` (2 or 3) FMU of `system` and copy
    it to `path`. `platforms`: the binaries/ folders to build (fmu.platforms.resolve: None the
    host's, "all", or () for a source-only FMU)."""
    path = Path(path)
    chosen = resolve(platforms)
    _check_platforms(system, chosen)
    files = _files(system, GUID_PLACEHOLDER, check_fmi_version(fmi_version))
    key = _key(files, chosen)
    cached = cache.cached_path(key, ".fmu")
    if not cached.exists():
        with tempfile.TemporaryDirectory() as tmp:
            fresh = Path(tmp) / "model.fmu"
            _write_fmu(_with_guid(files, key), _source_files(system, fmi_version),
                       model_identifier(system), chosen, fmi_version, fresh)
            cache.store(key, ".fmu", fresh)
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cached, path)
    return path
