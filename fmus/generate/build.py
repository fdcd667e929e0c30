"""Compile + package + validate: a model definition becomes a co-simulation .fmu.

The archive holds modelDescription.xml, binaries/linux64/<id>.so, sources/ (everything needed
to rebuild on another platform: runtime, generated code, FMI headers), documentation/ and
resources/. The GUID hashes the interface and the code, so an unchanged model is not rebuilt.
"""

from __future__ import annotations

import hashlib
import html
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from typing import TYPE_CHECKING

from railfmu.fmus.cache import cache_root

if TYPE_CHECKING:
    from railfmu.models.base import Model
# codegen (sympy) is imported where a model is generated: the up-to-date check of a run whose
# FMUs are current must not load sympy

HERE = Path(__file__).resolve().parent
FMUS = HERE.parent
RUNTIME_DIR = FMUS / "native" / "runtime"
CSRC_DIR = FMUS / "native" / "models"
COMMON_DIR = FMUS / "native" / "common"  # C shared by several models: RNG, CSV tables, spectra
PLATFORM = "linux64"
PLATFORM_FMI3 = "x86_64-linux"  # FMI 3.0 names platforms by tuple (FMI 3.0, 2.5.1.1)
FMI3_PLATFORMS = {"linux64": PLATFORM_FMI3, "win64": "x86_64-windows"}
CFLAGS = ["-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror"]
# FMI 2 platform folder -> (default compiler, the environment variable that overrides it, library
# suffix, flags added to CFLAGS). win64: mingw-w64 with SSE2 arithmetic as on x86-64 Linux (never
# x87 extended precision, so both binaries compute the same doubles) and libgcc linked in, so the
# DLL needs only KERNEL32.dll and msvcrt.dll; stripped (-s), since the debug sections of mingw's
# own start-up code would make it 3.6 times larger. The fmi2 functions are exported by
# FMI2_Export (__declspec(dllexport) in fmi2Functions.h), and nothing else is.
PLATFORMS = {
    "linux64": ("gcc", "CC", ".so", []),
    "win64": ("x86_64-w64-mingw32-gcc", "CC_WIN64", ".dll", ["-msse2", "-mfpmath=sse", "-static-libgcc", "-s"]),
}
FMI_HEADERS = ["fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"]
# FMI 3.0: fmi3_runtime.c maps the fmi3 functions onto the FMI 2 runtime it includes
FMI3_HEADERS = ["fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"]
FMI_VERSIONS = (2, 3)
# Extra flags for every FMU, e.g. "-fsanitize=address,undefined" (`make sanitize`, with
# RAILFMU_CACHE elsewhere); part of sources_key, so they never mix with a normal build.
EXTRA_CFLAGS_ENV = "RAILFMU_EXTRA_CFLAGS"
_ZIP_DATE = (2020, 1, 1, 0, 0, 0)  # fixed timestamps: the same model gives the same archive


class BuildError(RuntimeError):
    """A model could not be generated, compiled or packaged."""


def cflags(platform: str = PLATFORM) -> list[str]:
    """The flags for ``platform``; RAILFMU_EXTRA_CFLAGS (sanitizers) only for the native one."""
    extra = os.environ.get(EXTRA_CFLAGS_ENV, "").split() if platform == PLATFORM else []
    return [*CFLAGS, *PLATFORMS[platform][3], *extra]


def compiler(platform: str = PLATFORM) -> str:
    default, env, _, _ = PLATFORMS[platform]
    return os.environ.get(env, default)


def default_platforms() -> tuple[str, ...]:
    """linux64, and win64 where its cross-compiler is installed (the second platform adds its
    compile time to the sympy derivation both share, once per version of the sources;
    docs/interoperability.md, Windows)."""
    return (PLATFORM, *(["win64"] if shutil.which(compiler("win64")) else []))


def _platforms(platforms) -> tuple[str, ...]:
    if platforms is None:
        return default_platforms()
    platforms = tuple(dict.fromkeys(platforms))
    unknown = [p for p in platforms if p not in PLATFORMS]
    if unknown or not platforms:
        raise BuildError(f"platform {', '.join(unknown) or '(none)'}: not one of {', '.join(PLATFORMS)}")
    return platforms


def fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


_INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]+"([^"]+)"', re.M)


def _native_source(name: str) -> Path | None:
    for d in (CSRC_DIR, COMMON_DIR):
        if (d / name).is_file():
            return d / name
    return None


def _add_includes(src: dict[str, str]) -> None:
    """Adds what the sources #include "..." from fmus/native (recursively), and X.c beside
    every included X.h, so sources/ rebuilds the FMU on its own and a model lists only its
    own files."""
    todo = list(src)
    while todo:
        for inc in _INCLUDE.findall(src[todo.pop()]):
            if inc in src or inc == "model_config.h":  # model_config.h: generated last
                continue
            path = _native_source(inc)
            if path is None:
                raise BuildError(f'#include "{inc}" is in neither {CSRC_DIR} nor {COMMON_DIR}')
            src[inc] = path.read_text()
            todo.append(inc)
            impl = path.with_suffix(".c")
            if path.suffix == ".h" and impl.is_file() and impl.name not in src:
                src[impl.name] = impl.read_text()
                todo.append(impl.name)


def _check_version(fmi_version: int) -> int:
    if fmi_version not in FMI_VERSIONS:
        raise BuildError(f"FMI version {fmi_version!r}: railfmu builds FMI 2.0 and 3.0 (2 or 3)")
    return fmi_version


def generate_sources(model: Model, fmi_version: int = 2) -> tuple[str, dict[str, str]]:
    """The GUID (FMI 3: instantiation token), and file name -> text of everything in the
    FMU's sources/."""
    src: dict[str, str] = {
        "fmi2_runtime.c": (RUNTIME_DIR / "fmi2_runtime.c").read_text(),
        "model.h": (RUNTIME_DIR / "model.h").read_text(),
    }
    headers = FMI_HEADERS
    if _check_version(fmi_version) == 3:
        src["fmi3_runtime.c"] = (RUNTIME_DIR / "fmi3_runtime.c").read_text()
        headers = [*FMI_HEADERS, *FMI3_HEADERS]
    for h in headers:
        src[h] = (fmi_header_dir() / h).read_text()
    from railfmu.fmus.generate import codegen  # sympy: only when a model is generated

    src[f"{model.identifier}_variables.c"] = codegen.variables_c(model)
    if model.generated:
        src[f"{model.identifier}_equations.c"] = codegen.equations_c(model)
    else:
        for name in model.c_sources:
            path = _native_source(name)
            if path is None:
                raise BuildError(f"{model.identifier}: hand-written source {CSRC_DIR / name} does not exist")
            src[name] = path.read_text()
    _add_includes(src)
    guid = codegen.guid_of(model, src, fmi_version)
    src["model_config.h"] = codegen.model_config_h(model, guid)
    return guid, src


_XML_LOCK = threading.Lock()  # libxml2 schema parsing (fmpy validates every modelDescription) is not thread-safe


def _guid_of_fmu(path: Path) -> str | None:
    try:
        from fmpy import read_model_description

        with _XML_LOCK:  # build_all's threads: concurrent parses hung or failed with "Internal error"
            return read_model_description(str(path)).guid
    except Exception:  # unreadable or foreign: rebuild
        return None


def sources_key() -> str:
    """A hash of the bytes of everything an FMU is generated from: the model definitions
    (models/, with their data and the build list), the generator, the runtime and
    hand-written C, the FMI headers' fmpy version, the native compiler and flags. Reading bytes
    takes milliseconds; deriving the models (sympy) takes seconds, so the up-to-date check never
    derives (a Monte Carlo member pays it on every run). The platforms built are not in it (the
    other platforms' flags are in build.py, which is): whether mingw-w64 is on a process's PATH
    must not move the FMUs to another folder, so a worker or a process with a bare PATH finds the
    FMUs built, and :func:`_has_binaries` says whether they carry the binaries asked for."""
    import fmpy

    h = hashlib.sha256(repr((cflags(), compiler(), fmpy.__version__)).encode())
    roots = [FMUS.parent / "models", RUNTIME_DIR, CSRC_DIR, COMMON_DIR]
    files = [f for r in roots for f in sorted(r.rglob("*")) if f.is_file() and "__pycache__" not in f.parts]
    files += [HERE / "codegen.py", HERE / "build.py", FMUS / "units.py"]
    for f in files:
        h.update(f.relative_to(FMUS.parent).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def default_out(fmi_version: int = 2) -> Path:
    """Where ``railfmu build`` and every run put the FMUs: one folder of the cache per
    :func:`sources_key`, so two versions of railfmu never overwrite each other's FMUs; the
    FMI 3.0 FMUs (same file names) in a sibling folder ending in ``-fmi3``."""
    key = sources_key()[:16]
    return cache_root() / "fmus" / (key if _check_version(fmi_version) == 2 else f"{key}-fmi3")


def definition_key(model: Model | str, fmi_version: int = 2) -> str:
    """The key of one FMU (a model or its identifier): :func:`sources_key` and its name. Equal
    keys give equal FMUs, so a build can be skipped without running the generator (sympy
    takes ~15 s on the full-vehicle model)."""
    identifier = model if isinstance(model, str) else model.identifier
    version = "" if fmi_version == 2 else f" fmi{fmi_version}"  # FMI 2 keys as before
    return hashlib.sha256(f"{sources_key()} {identifier}{version}".encode()).hexdigest()


def _manifest(out_dir: Path) -> Path:
    return out_dir / ".railfmu-build.key"


def _manifest_key(fmi_version: int) -> str:
    """:func:`sources_key`, and the FMI version unless 2: one folder never passes for the other."""
    return sources_key() + ("" if fmi_version == 2 else f" fmi{fmi_version}")


def _current_from_manifest(out_dir: Path, fmi_version: int = 2, platforms=(PLATFORM,)) -> list[Path] | None:
    """The FMUs of the last full build when nothing they come from has changed since
    (:func:`sources_key`) and each is still the one built then (its GUID), with the binaries of
    ``platforms``; else None."""
    manifest = _manifest(out_dir)
    if not manifest.is_file():
        return None
    key, *rows = manifest.read_text().split("\n")
    if key != _manifest_key(fmi_version):
        return None
    paths = []
    for row in filter(None, rows):
        identifier, _, guid = row.partition(" ")
        target = out_dir / f"{identifier}.fmu"
        if _guid_in_archive(target) != guid or not _has_binaries(target, platforms, fmi_version):
            return None
        paths.append(target)
    return paths


def _guid_in_archive(path: Path) -> str | None:
    """The guid (FMI 3: instantiationToken) attribute of the archive's modelDescription.xml,
    without parsing the rest."""
    try:
        with zipfile.ZipFile(path) as zf:
            head = zf.read("modelDescription.xml")[:4096].decode("utf-8", "replace")
    except (OSError, KeyError, zipfile.BadZipFile):
        return None
    m = re.search(r'\b(?:guid|instantiationToken)="([^"]*)"', head)
    return m.group(1) if m else None


def _key_file(target: Path) -> Path:
    return target.with_name(f".{target.stem}.key")


def binary_folder(platform: str, fmi_version: int = 2) -> str:
    """The folder under binaries/: FMI 2 names platforms ``linux64``/``win64``, FMI 3.0 by tuple
    (FMI 3.0, 2.5.1.1)."""
    return platform if fmi_version == 2 else FMI3_PLATFORMS[platform]


def _has_binaries(path: Path, platforms: tuple[str, ...], fmi_version: int = 2) -> bool:
    try:
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
    except (OSError, zipfile.BadZipFile):
        return False
    return all(f"binaries/{binary_folder(p, fmi_version)}/{path.stem}{PLATFORMS[p][2]}" in names
               for p in platforms)


def _no_compiler(platform: str) -> str:
    hint = "set CC or install gcc" if platform == PLATFORM else \
        f"set {PLATFORMS[platform][1]} or install gcc-mingw-w64-x86-64"
    return f"{platform} C compiler {compiler(platform)!r} not found ({hint})"


def _compile(model: Model, root: Path, c_files: list[str], platform: str, fmi_version: int = 2) -> None:
    """sources/ -> binaries/<platform folder>/<identifier>.so|.dll."""
    binary = root / "binaries" / binary_folder(platform, fmi_version) / f"{model.identifier}{PLATFORMS[platform][2]}"
    binary.parent.mkdir(parents=True)
    cc = compiler(platform)
    cmd = [cc, *cflags(platform), "-I", str(root / "sources"), "-o", str(binary),
           *[str(root / "sources" / f) for f in c_files], "-lm"]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True)
    except FileNotFoundError as exc:
        raise BuildError(_no_compiler(platform)) from exc
    if res.returncode != 0:
        raise BuildError(f"{model.identifier}: {platform} compilation failed:\n{res.stderr.strip()}")


def build_fmu(model: Model, out_dir: Path | str | None = None, force: bool = False,
              fmi_version: int = 2, platforms=None) -> Path:
    """Build ``<out_dir>/<identifier>.fmu`` for FMI ``fmi_version`` (2 or 3); returns its
    path. Skips everything when the FMU there was built from the same definitions
    (:func:`definition_key`), and the compiler when an FMU with the same GUID and binaries is
    already there (unless ``force``). ``platforms``: the binaries it carries (``linux64``,
    ``win64``; default :func:`default_platforms`)."""
    platforms = _platforms(platforms)
    out_dir = default_out(fmi_version) if out_dir is None else Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{model.identifier}.fmu"
    key = definition_key(model, fmi_version)
    key_file = _key_file(target)
    if not force and target.exists() and key_file.is_file():
        recorded_key, _, recorded_guid = key_file.read_text().partition(" ")
        if (recorded_key == key and _guid_of_fmu(target) == recorded_guid.strip()
                and _has_binaries(target, platforms, fmi_version)):
            return target
    from railfmu.fmus.generate import codegen

    guid, src = generate_sources(model, fmi_version)
    # FMI 3: fmi3_runtime.c includes fmi2_runtime.c, which is not compiled on its own
    c_files = sorted(n for n in src if n.endswith(".c") and not (fmi_version == 3 and n == "fmi2_runtime.c"))
    if fmi_version == 3:
        src["buildDescription.xml"] = codegen.build_description_fmi3(model, c_files)
    if (not force and target.exists() and _guid_of_fmu(target) == guid
            and _has_binaries(target, platforms, fmi_version)):
        key_file.write_text(f"{key} {guid}\n")
        return target
    with tempfile.TemporaryDirectory(prefix=f"railfmu-{model.identifier}-") as tmp:
        root = Path(tmp)
        (root / "sources").mkdir()
        for name, text in src.items():
            (root / "sources" / name).write_text(text)
        (root / "modelDescription.xml").write_text(
            codegen.model_description(model, guid, c_files) if fmi_version == 2
            else codegen.model_description_fmi3(model, guid))
        for platform in platforms:
            _compile(model, root, c_files, platform, fmi_version)
        doc = root / "documentation"
        doc.mkdir()
        (doc / "_main.html").write_text(
            f"<html><head><meta charset='utf-8'><title>{model.identifier}</title></head><body>"
            f"<h1>{model.identifier}</h1><p>{html.escape(model.description)}</p>"
            f"<pre>{html.escape(model.documentation or '')}</pre></body></html>\n")
        res_dir = root / "resources"
        res_dir.mkdir()
        for name, path in model.resources.items():
            shutil.copy(path, res_dir / name)
        tmp_fmu = out_dir / f".{model.identifier}.fmu.part"
        with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(root.rglob("*")):
                arc = path.relative_to(root).as_posix() + ("/" if path.is_dir() else "")
                info = zipfile.ZipInfo(arc, date_time=_ZIP_DATE)
                if path.is_dir():
                    info.external_attr = 0o40755 << 16
                    zf.writestr(info, b"")
                else:
                    info.external_attr = (0o755 if path.suffix in (".so", ".dll") else 0o644) << 16
                    info.compress_type = zipfile.ZIP_DEFLATED
                    zf.writestr(info, path.read_bytes())
        tmp_fmu.replace(target)  # atomic: a reader never sees a half-written FMU
    key_file.write_text(f"{key} {guid}\n")
    return target


def build_all(out_dir: Path | str | None = None, models: list[Model] | None = None,
              force: bool = False, progress: bool = True, fmi_version: int = 2,
              platforms=None) -> list[Path]:
    """Build every model (``models``, default the build list ``railfmu.models.all_models``) for
    FMI ``fmi_version`` (2 or 3) into ``out_dir`` (default :func:`default_out`); when the whole
    list is asked for and :func:`sources_key` is the one of its last build, returns its FMUs
    without deriving any model. ``progress`` prints a line per FMU to stderr when anything is
    built. ``platforms``: as for :func:`build_fmu`."""
    platforms = _platforms(platforms)
    out_dir = default_out(fmi_version) if out_dir is None else Path(out_dir)
    if models is None and not force:
        current = _current_from_manifest(out_dir, fmi_version, platforms)
        if current is not None:
            return current
    from railfmu.models import all_models

    for platform in platforms:  # before deriving any model (seconds)
        if shutil.which(compiler(platform)) is None:
            raise BuildError(_no_compiler(platform))
    everything = models is None
    models = all_models() if models is None else models
    key = _manifest_key(fmi_version)  # before building: an edit during the build must not be recorded as built
    done = [0]
    if progress:
        print(f"railfmu: building {len(models)} FMI {fmi_version}.0 FMUs for {', '.join(platforms)} into "
              f"{out_dir} (once per version of the sources, ~30 s)", file=sys.stderr, flush=True)

    def one(m: Model) -> Path:
        path = build_fmu(m, out_dir, force, fmi_version, platforms)
        if progress:
            with _XML_LOCK:
                done[0] += 1
                print(f"  [{done[0]}/{len(models)}] {m.identifier}", file=sys.stderr, flush=True)
        return path

    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        paths = list(pool.map(one, models))
    if everything:
        rows = [f"{p.stem} {_guid_in_archive(p)}" for p in paths]
        tmp = _manifest(out_dir).with_name(f".railfmu-build.{os.getpid()}.part")
        tmp.write_text("\n".join([key, *rows]) + "\n")
        tmp.replace(_manifest(out_dir))  # atomic: parallel builders never read half a manifest
    return paths


def validate(path: Path | str, packaging: bool | None = None) -> list[str]:
    """Every problem of an FMU: FMI conformance for any FMU (FMPy's validation of
    modelDescription.xml: schema, units, variable and dependency rules; a ZIP archive with a
    binary or sources), then railfmu's own packaging rules (a linux64 binary and the C
    sources) when ``packaging`` is true, or, when it is None, for an FMU railfmu built (its
    generationTool): another tool's FMU that conforms is not broken for lacking them."""
    from fmpy.validation import validate_fmu

    path = Path(path)
    if path.is_file() and not zipfile.is_zipfile(path):
        return [f"{path.name} is not a ZIP archive"]
    problems = list(validate_fmu(str(path)))
    if not path.is_file():
        return problems
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    if not any(n.startswith("binaries/") and not n.endswith("/") for n in names) \
            and not any(n.startswith("sources/") for n in names):
        problems.append("neither binaries/ nor sources/: nothing can run it")
    folders = sorted({(binary_folder(p, v), s) for p, (_, _, s, _) in PLATFORMS.items() for v in FMI_VERSIONS})
    for folder, suffix in folders:  # a platform's folder holds its library
        members = [n for n in names if n.startswith(f"binaries/{folder}/") and not n.endswith("/")]
        if members and not any(n.endswith(suffix) for n in members):
            problems.append(f"binaries/{folder}/ has no {suffix} library")
    if packaging is None:
        packaging = built_by_railfmu(path)
    if packaging:
        if not any(n.startswith(f"binaries/{f}/") and n.endswith(suffix) for f, suffix in folders for n in names):
            problems.append(f"no binary in {' or '.join(sorted(f'binaries/{f}/' for f, _ in folders))} "
                            "(railfmu's packaging)")
        if not any(n.startswith("sources/") and n.endswith(".c") for n in names):
            problems.append("no C sources in sources/ (railfmu's packaging)")
    return problems


def built_by_railfmu(path: Path | str) -> bool:
    """Whether railfmu generated the FMU (modelDescription generationTool "railfmu")."""
    try:
        from fmpy import read_model_description

        from railfmu.fmus.generate import GENERATOR

        return (read_model_description(str(path), validate=False).generationTool or "").split(" ")[0] == GENERATOR
    except Exception:  # noqa: BLE001 - unreadable: FMPy's validation says why
        return False


def describe(path: Path | str) -> str:
    """``FMI 2.0 Co-Simulation, by OpenModelica ...``: what an FMU is, for validate's report."""
    try:
        from fmpy import read_model_description

        md = read_model_description(str(path), validate=False)
    except Exception:  # noqa: BLE001
        return "unreadable"
    kinds = [k for k, v in (("Co-Simulation", md.coSimulation), ("Model Exchange", md.modelExchange),
                            ("Scheduled Execution", getattr(md, "scheduledExecution", None))) if v is not None]
    tool = f", by {md.generationTool}" if md.generationTool else ""
    return f"FMI {md.fmiVersion} {' and '.join(kinds) or '(no interface)'}{tool}"
