"""An SSP is untrusted input: unpacking is bounded (total size, compression ratio, member
count; each limit named in a one-line error with the variable that raises it) and its XML
may carry no DTD (billion laughs, external entities)."""

import shutil
import time
import zipfile
import zlib

import pytest

from railfmu.fmus.ssp import read_system
from railfmu.fmus.ssp.xmltools import locate, parse_xml
from railfmu.models.errors import UserError

GB = 1 << 30


class _RepeatedZeros:
    """A deflate compressor for a stream of 16 MiB zero blocks: each block compresses (after a
    full flush) to the same bytes, so they are computed once and the 2 GiB bomb takes ~2 s to
    write (zipfile still computes the real CRC), not the ~15 s of compressing it."""

    def __init__(self):
        c = zlib.compressobj(9, zlib.DEFLATED, -15)
        self.block = c.compress(bytes(BLOCK)) + c.flush(zlib.Z_FULL_FLUSH)
        self.end = c.flush()

    def compress(self, data):
        assert len(data) == BLOCK and not data.count(1)
        return self.block

    def flush(self):
        return self.end


BLOCK = 1 << 24


@pytest.fixture(scope="module")
def bomb(tmp_path_factory):
    """A ~2 MB .ssp whose one member unpacks to 2 GiB of zeros (written as a stream; a real,
    valid archive: zipfile unpacks it, given the room)."""
    path = tmp_path_factory.mktemp("bomb") / "bomb.ssp"
    zeros = bytes(BLOCK)
    mp = pytest.MonkeyPatch()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", "<x/>")
        mp.setattr(zipfile, "_get_compressor", lambda *a, **k: _RepeatedZeros())
        try:
            with zf.open("resources/zeros.csv", "w", force_zip64=True) as f:
                for _ in range(2 * GB // BLOCK):
                    f.write(zeros)
        finally:
            mp.undo()
    return path


def test_a_zip_bomb_is_refused_within_a_second(bomb):
    assert bomb.stat().st_size < 3e6
    t0 = time.perf_counter()
    with pytest.raises(UserError) as exc:
        locate(bomb)
    elapsed = time.perf_counter() - t0
    assert elapsed < 1.0
    msg = str(exc.value)
    assert "\n" not in msg and "zeros.csv" in msg and "RAILFMU_SSP_MAX_BYTES" in msg
    # a higher size limit leaves the ratio limit
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAILFMU_SSP_MAX_BYTES", str(4 * GB))
        with pytest.raises(UserError, match=r"zeros.csv: ratio [\d,]+ exceeds the limit of 200 .*RAILFMU_SSP_MAX_RATIO"):
            locate(bomb)


def test_the_bomb_is_a_real_archive(bomb):
    with zipfile.ZipFile(bomb) as zf:
        info = zf.getinfo("resources/zeros.csv")
        assert info.file_size == 2 * GB
        with zf.open(info) as f:  # decompresses, the first blocks at least
            assert f.read(3 * BLOCK) == bytes(3 * BLOCK)


def test_each_limit_is_named_and_can_be_raised(tmp_path, monkeypatch):
    path = tmp_path / "many.ssp"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", "<x/>")
        for k in range(20):
            zf.writestr(f"resources/{k}.txt", "a" * 1000)
    monkeypatch.setenv("RAILFMU_SSP_MAX_MEMBERS", "10")
    with pytest.raises(UserError, match=r"21 members exceeds the limit of 10 .*RAILFMU_SSP_MAX_MEMBERS"):
        locate(path)
    monkeypatch.setenv("RAILFMU_SSP_MAX_MEMBERS", "100")
    monkeypatch.setenv("RAILFMU_SSP_MAX_BYTES", "5000")
    with pytest.raises(UserError, match=r"bytes .*exceeds the limit of 5,000 .*RAILFMU_SSP_MAX_BYTES"):
        locate(path)
    monkeypatch.setenv("RAILFMU_SSP_MAX_BYTES", "1e6")
    assert (locate(path).dir / "resources" / "19.txt").read_text() == "a" * 1000
    monkeypatch.setenv("RAILFMU_SSP_MAX_BYTES", "lots")
    shutil.copy(path, tmp_path / "again.ssp")  # (an archive is unpacked once per process)
    with pytest.raises(UserError, match="RAILFMU_SSP_MAX_BYTES='lots': expected a positive number"):
        locate(tmp_path / "again.ssp")


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
  version="1.0" name="&lol9;"><ssd:System name="s"/></ssd:SystemStructureDescription>
"""

XXE = """<?xml version="1.0"?>
<!DOCTYPE ssd [ <!ENTITY secret SYSTEM "file://{secret}"> ]>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
  version="1.0" name="&secret;"><ssd:System name="s"/></ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("kind", ["billion_laughs", "xxe", "late_xxe"])
def test_entities_are_refused(tmp_path, kind):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET")
    ssd = tmp_path / "SystemStructure.ssd"
    text = BILLION_LAUGHS if kind == "billion_laughs" else XXE.format(secret=secret)
    if kind == "late_xxe":  # past the head read before parsing
        head, _, rest = text.partition("\n")
        text = head + "\n<!--" + "x" * 70_000 + "-->\n" + rest
    ssd.write_text(text)
    t0 = time.perf_counter()
    with pytest.raises(UserError) as exc:
        parse_xml(ssd, "x/SystemStructure.ssd")
    assert time.perf_counter() - t0 < 1.0
    assert "TOP-SECRET" not in str(exc.value)
    # late: libxml2 refuses the external entity itself (no network, entities not resolved)
    assert ("DOCTYPE" if kind != "late_xxe" else "external entity") in str(exc.value)
    with pytest.raises(UserError) as exc:  # the whole reader, too
        read_system(tmp_path)
    assert "TOP-SECRET" not in str(exc.value) and "\n" not in str(exc.value)
