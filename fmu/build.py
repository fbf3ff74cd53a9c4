"""build_fmu: System -> FMI 2.0 co-simulation FMU (generated C + generic wrapper, compiled, zipped).

The FMU holds modelDescription.xml, binaries/<platform>/<id>.so and sources/ (wrapper, generated
code, config.h and the FMI headers, listed in the XML's SourceFiles) so it can be rebuilt
elsewhere with `cc -shared -fPIC -Isources sources/*.c -lm -ldl -lpthread`. A System with an
embedded network has it in sources/ as generated C (flexff_net.c, runtime "c", the default) and
needs nothing else; with runtime "onnxruntime" the FMU gets the graph in resources/ and
onnxruntime's library beside its own in binaries/<platform>/, and its sources build only
against that library. A precomputation table goes to resources/ in either case. Builds are
cached by a hash of all their inputs; the GUID is derived from the same hash, so equal inputs
give a bit-equal FMU. `$FLEXFF_SANITIZE` builds the binaries with sanitizers
(fmu.compile.sanitizer_flags), under their own key. The library is built for the host alone
unless `platforms` (fmu.platforms) names others, or none for a source-only FMU; onnxruntime and
a network's own task refuse the platforms they cannot run on.
"""

from __future__ import annotations

import shutil
import tempfile
import uuid
import zipfile
from collections.abc import Sequence
from pathlib import Path

import fmpy

from flexff.fmu import cache
from flexff.fmu.codegen import NET_MODEL_FILE, NET_TABLE_FILE, generate_config_h, generate_model_c
from flexff.fmu.compile import CFLAGS, compiler_version, fmi_headers, run_compiler, sanitizer_flags
from flexff.fmu.errors import InputError
from flexff.fmu.layout import make_layout, model_identifier
from flexff.fmu.model_description import model_description_xml
from flexff.fmu.network import Network, runtime_library
from flexff.fmu.network_c import FMU_PREFIX, fmu_network_sources
from flexff.fmu.platforms import PLATFORMS, host, resolve
from flexff.fmu.system import System

C_DIR = Path(__file__).parent / "c"
# the generic wrapper (see c/wrapper.h), compiled with the generated model.c of each FMU
WRAPPER_C_FILES = ("fmi2Functions.c", "wrapper.c", "rng.c")
WRAPPER_HEADERS = ("wrapper.h", "rng.h")
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


def _source_files(system: System) -> list[str]:
    """The C files compiled into the FMU's library."""
    net = system.network
    if net is None:
        return [*WRAPPER_C_FILES, "model.c"]
    return [*WRAPPER_C_FILES, "model.c", *NETWORK_C_FILES, *RUNTIME_C_FILES[net.runtime],
            *([f"{FMU_PREFIX}.c"] if net.runtime == "c" else []),
            *(TASK_C_FILES if net.task else ())]


def _files(system: System, guid: str) -> dict[str, str | bytes]:
    """Every file of the FMU but its compiled library, by archive path."""
    identifier = model_identifier(system)
    layout = make_layout(system)
    net = system.network
    generic = (*WRAPPER_C_FILES, *WRAPPER_HEADERS,
               *((*NETWORK_C_FILES, *NETWORK_HEADERS, *RUNTIME_C_FILES[net.runtime],
                  *RUNTIME_HEADERS[net.runtime]) if net else ()),
               *(TASK_C_FILES if net and net.task else ()))
    sources = {
        **{name: (C_DIR / name).read_text() for name in generic},
        "config.h": generate_config_h(system, layout, identifier, guid),
        **generate_model_c(system, identifier),
        **(fmu_network_sources(net.model) if net and net.runtime == "c" else {}),
        **fmi_headers(),
    }
    files: dict[str, str | bytes] = {f"sources/{name}": text for name, text in sources.items()}
    files["modelDescription.xml"] = model_description_xml(system, layout, identifier, guid,
                                                          _source_files(system))
    if system.network:
        files.update(_network_files(system.network, [u.name for u in system.inputs]))
    return files


def _network_files(net: Network, input_names: list[str]) -> dict[str, bytes]:
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
        files[f"binaries/{fmpy.platform}/{library.name}"] = library.read_bytes()
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
    if net is not None and net.task and "win64" in platforms:
        raise InputError("a network in its own task (--task) needs Linux threads: build it "
                         "for linux64 and aarch64-linux, not win64")


def fmu_key(system: System, platforms: Sequence[str] | None = None) -> str:
    """sha256 of everything that goes into the build of `system` for `platforms` (as
    build_fmu takes them); its GUID derives from it."""
    return _key(_files(system, GUID_PLACEHOLDER), resolve(platforms))


def _with_guid(files: dict[str, str | bytes], key: str) -> dict[str, str | bytes]:
    """The files with the placeholder replaced by the GUID derived from the key."""
    guid = "{" + str(uuid.UUID(key[:32])) + "}"
    return {name: text.replace(GUID_PLACEHOLDER, guid)
            if name in GUID_FILES and isinstance(text, str) else text
            for name, text in files.items()}


def _write_fmu(files: dict[str, str | bytes], sources: list[str], identifier: str,
               platforms: tuple[str, ...], target: Path) -> None:
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
            files[f"binaries/{name}/{library.name}"] = library.read_bytes()
        with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, ZIP_DATE)
                if name.startswith("binaries/"):
                    info.external_attr = 0o755 << 16
                zf.writestr(info, files[name], zipfile.ZIP_DEFLATED)


def build_fmu(system: System, path: str | Path, platforms: Sequence[str] | None = None) -> Path:
    """Build (or fetch from the cache) the FMU of `system` and copy it to `path`. `platforms`:
    the binaries/ folders to build (fmu.platforms.resolve: None the host's, "all", or () for
    a source-only FMU)."""
    path = Path(path)
    chosen = resolve(platforms)
    _check_platforms(system, chosen)
    files = _files(system, GUID_PLACEHOLDER)
    key = _key(files, chosen)
    cached = cache.cached_path(key, ".fmu")
    if not cached.exists():
        with tempfile.TemporaryDirectory() as tmp:
            fresh = Path(tmp) / "model.fmu"
            _write_fmu(_with_guid(files, key), _source_files(system), model_identifier(system),
                       chosen, fresh)
            cache.store(key, ".fmu", fresh)
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cached, path)
    return path
