"""Where an SSP's files are, and its XML parsed and checked against the SSP 1.0 or 2.0 schemas.

An SSP is a folder (or a ``.ssp`` zip) whose ``SystemStructure.ssd`` refers to FMUs, ``.ssv``
and ``.ssm`` files by URIs relative to that folder: the SSP root. Messages name files as the
user gave them (``experiments/x/variants/a.ssv``, ``x.ssp/SystemStructure.ssd``), never the
temporary folder an archive is extracted into.
"""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote, urlparse

import fmpy
from lxml import etree

from railfmu.models.errors import UserError

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
SSM_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
RF_NS = "https://railfmu.org/ssp/1"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"  # OMSimulator's
NS = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": SSV_NS, "ssm": SSM_NS, "rf": RF_NS, "osp": OSP_NS, "oms": OMS_NS}

SCHEMA_DIR = Path(fmpy.__file__).parent / "ssp" / "schema"
# SSP 2.0 keeps the SSP1 namespaces and tells itself apart by version="2.0"; its schemas (from
# the standard, BSD 2-clause) add the sized types (ssc:Float64, Int32, ...), Enumeration and
# Binary connectors and new attributes
SCHEMA_DIR_2 = Path(__file__).parent / "schema2"
_SCHEMA_FILES = {"ssd": "SystemStructureDescription.xsd", "ssv": "SystemStructureParameterValues.xsd",
                 "ssm": "SystemStructureParameterMapping.xsd"}
#: SSP 2.0's sized types (ssc: on connectors, ssv: in parameter sets) as the FMI 2.0 type they carry
SIZED_TYPES = {"Float64": "Real", "Float32": "Real",
               **{t: "Integer" for t in ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")}}
# no DTDs, no entities, no network: an SSP is untrusted input
_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)


def one_line(text: object) -> str:
    return " ".join(str(text).split())


def local(el) -> str:
    """An element's tag without its namespace."""
    return etree.QName(el).localname


def children(el, ns: str | None = None):
    """Element children (no comments), optionally of one namespace."""
    return [c for c in el if isinstance(c.tag, str) and (ns is None or etree.QName(c).namespace == ns)]


# -- the SSP root --------------------------------------------------------------------------

@dataclass
class Root:
    given: Path  # what the caller passed
    dir: Path  # the SSP root: relative URIs resolve here
    ssd: Path
    label: Path  # how ``dir`` is shown in messages

    def show(self, path: Path) -> str:
        try:
            return str(self.label / path.relative_to(self.dir))
        except ValueError:
            return str(path)

    def resolve(self, uri: str, where: str) -> Path:
        """A relative (or ``file:``) URI of the SSD as a path; other schemes are not supported."""
        parsed = urlparse(uri)
        if parsed.scheme not in ("", "file"):
            raise UserError(f"{where}: source {uri!r}: only relative and file: URIs are supported")
        path = Path(unquote(parsed.path))
        return path if path.is_absolute() else self.dir / path


def locate(path) -> Root:
    """The SSP root of a ``.ssd`` file, a folder holding ``SystemStructure.ssd``, or a ``.ssp``."""
    given = Path(path)
    if not given.exists():
        raise UserError(f"{given}: no such file or directory")
    if given.is_dir():
        ssd = given / "SystemStructure.ssd"
        if not ssd.is_file():
            raise UserError(f"{given}: no SystemStructure.ssd in this folder")
        return Root(given, given, ssd, given)
    if given.suffix.lower() == ".ssd":
        return Root(given, given.parent, given, given.parent)
    if given.suffix.lower() == ".ssp" or zipfile.is_zipfile(given):
        folder = _extract(given)
        if not (folder / "SystemStructure.ssd").is_file():
            raise UserError(f"{given}: no SystemStructure.ssd at the top of the archive")
        return Root(given, folder, folder / "SystemStructure.ssd", given)
    raise UserError(f"{given}: expected a .ssd file, a .ssp archive or a folder holding SystemStructure.ssd")


_EXTRACTED: dict[tuple, Path] = {}

# Unpacking limits (an SSP is untrusted input: a 2 MB archive can unpack to terabytes). The
# sizes are the members' declared ones, which zipfile never exceeds when extracting.
LIMITS = {  # env var: (default, what it bounds)
    "RAILFMU_SSP_MAX_BYTES": (1 << 30, "total unpacked size in bytes"),
    "RAILFMU_SSP_MAX_MEMBERS": (10_000, "number of members"),
    "RAILFMU_SSP_MAX_RATIO": (200, "compression ratio of a member over 1 MiB"),
}
_RATIO_FROM = 1 << 20  # small members may compress well; only large ones can bomb


def limit(name: str) -> int:
    default = LIMITS[name][0]
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(float(text))
    except ValueError:
        raise UserError(f"{name}={text!r}: expected a positive number") from None
    if value < 1:
        raise UserError(f"{name}={text!r}: expected a positive number")
    return value


def _check_limits(archive: Path, infos: list[zipfile.ZipInfo]) -> None:
    def refuse(name: str, found: str) -> None:
        raise UserError(f"{archive}: refused to unpack: {found} exceeds the limit of {limit(name):,} "
                        f"({LIMITS[name][1]}); raise it with the environment variable {name} if the "
                        "archive is trusted")

    if len(infos) > limit("RAILFMU_SSP_MAX_MEMBERS"):
        refuse("RAILFMU_SSP_MAX_MEMBERS", f"{len(infos):,} members")
    total = 0
    for info in infos:
        total += info.file_size
        if total > limit("RAILFMU_SSP_MAX_BYTES"):
            refuse("RAILFMU_SSP_MAX_BYTES", f"{total:,} bytes (at {info.filename})")
        ratio = info.file_size / max(info.compress_size, 1)
        if info.file_size > _RATIO_FROM and ratio > limit("RAILFMU_SSP_MAX_RATIO"):
            refuse("RAILFMU_SSP_MAX_RATIO", f"{info.filename}: ratio {ratio:,.0f}")


def _extract(archive: Path) -> Path:
    """Unpack a .ssp once per process (per version of the file); removed at exit, because the
    FMU paths of the System point inside it."""
    if not zipfile.is_zipfile(archive):
        raise UserError(f"{archive}: not an SSP archive (not a ZIP file)")
    st = archive.stat()
    key = (archive.resolve(), st.st_mtime_ns, st.st_size)
    if key in _EXTRACTED and _EXTRACTED[key].is_dir():
        return _EXTRACTED[key]
    folder = Path(tempfile.mkdtemp(prefix="railfmu-ssp-"))
    atexit.register(shutil.rmtree, folder, True)
    try:
        with zipfile.ZipFile(archive) as zf:
            _check_limits(archive, zf.infolist())
            zf.extractall(folder)  # zipfile drops '..' and absolute member names
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, RuntimeError, ValueError) as exc:
        raise UserError(f"{archive}: cannot unpack the SSP archive: {one_line(exc)}") from None
    _EXTRACTED[key] = folder
    return folder


# -- XML and schema ------------------------------------------------------------------------

@functools.cache
def schema(kind: str, version: str = "1.0") -> etree.XMLSchema:
    folder = SCHEMA_DIR_2 if version == "2.0" else SCHEMA_DIR
    return etree.XMLSchema(etree.parse(str(folder / _SCHEMA_FILES[kind])))


def ssp_version(el, shown: str) -> str:
    """"1.0" or "2.0": which SSP a document (or an inline parameter set) is, by its version
    attribute; any other version is refused in one line before a schema sees it."""
    text = (el.get("version") or "1.0").strip()
    if text == "2.0" or text.startswith("2.0."):
        return "2.0"
    if text.startswith("1."):
        return "1.0"
    raise UserError(f"{shown}:{el.sourceline}: SSP version {text!r} is not supported (SSP 1.0 and 2.0 are)")


def _short(message: str) -> str:
    """lxml writes '{http://ssp-standard.org/...}Connection'; we write 'ssd:Connection'."""
    for prefix, uri in NS.items():
        message = message.replace("{" + uri + "}", prefix + ":")
    return one_line(message)


def schema_problems(el, kind: str, shown: str) -> list[str]:
    """Every schema error of a document (or an inline ssv:ParameterSet/ssm:ParameterMapping),
    as 'file:line: schema: message'. The SSD 1.0 schema takes inline parameter sets and
    mappings as lax 'any' content, so those are checked against their own schemas here."""
    try:
        s = schema(kind, ssp_version(el, shown))
    except UserError as exc:
        return [str(exc)]
    problems = []
    if not s.validate(el):
        problems += [f"{shown}:{e.line}: schema: {_short(e.message)}" for e in s.error_log]
    if kind == "ssd":
        for inline in el.iterfind(".//ssd:ParameterValues/ssv:ParameterSet", NS):
            problems += schema_problems(inline, "ssv", shown)
        for inline in el.iterfind(".//ssd:ParameterMapping/ssm:ParameterMapping", NS):
            problems += schema_problems(inline, "ssm", shown)
    return problems


def parse_xml(file: Path, shown: str):
    """The root element of an XML file; malformed or unreadable -> UserError."""
    # SSP files need no DTD; one is how entity bombs (billion laughs) and external entities
    # (XXE) come in: refused before parsing (libxml2 would expand entities in attributes even
    # with resolve_entities=False, up to its amplification limit), and after it as a backstop
    # for a DOCTYPE further down than the head read here
    try:
        with open(file, "rb") as f:
            head = f.read(1 << 16)
    except OSError as exc:
        raise UserError(f"{shown}: cannot read: {one_line(exc.strerror or exc)}") from None
    if b"<!DOCTYPE" in head:
        raise UserError(f"{shown}: a DOCTYPE (DTD, entities) is not allowed in an SSP file")
    try:
        tree = etree.parse(str(file), _PARSER)
    except etree.XMLSyntaxError as exc:
        raise UserError(f"{shown}:{exc.lineno}: malformed XML: {one_line(exc.msg)}") from None
    except OSError as exc:
        raise UserError(f"{shown}: cannot read: {one_line(exc.strerror or exc)}") from None
    if tree.docinfo.internalDTD is not None or tree.docinfo.doctype:
        raise UserError(f"{shown}: a DOCTYPE (DTD, entities) is not allowed in an SSP file")
    return tree.getroot()


def parse_checked(file: Path, kind: str, shown: str):
    """Parse and validate against the SSP 1.0 or 2.0 schema of ``kind`` (ssd, ssv, ssm); the first
    problem is raised as a one-line UserError."""
    el = parse_xml(file, shown)
    expected = {"ssd": (SSD_NS, "SystemStructureDescription"), "ssv": (SSV_NS, "ParameterSet"),
                "ssm": (SSM_NS, "ParameterMapping")}[kind]
    q = etree.QName(el)
    if (q.namespace, q.localname) != expected:
        raise UserError(f"{shown}:{el.sourceline}: expected an {kind}:{expected[1]} document "
                        f"(namespace {expected[0]}), found {_short(el.tag)}")
    problems = schema_problems(el, kind, shown)
    if problems:
        raise UserError(problems[0])
    return el
