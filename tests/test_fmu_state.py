"""FMU states are typed and checked (fmus/native/runtime/fmi2_runtime.c): a state saved or
serialized by one FMU and handed to another, or damaged (random, truncated, bit-flipped,
forged), is refused with fmi2Error and a logged reason, and the instance goes on as before.

A bounded, seeded fuzz: RAILFMU_FUZZ_SEED (default 0) and RAILFMU_FUZZ_CASES (cases per FMU
and kind, default 60). `make sanitize` runs it against FMUs built with ASan + UBSan, where an
out-of-bounds read or write aborts the process instead of passing silently.
"""

from __future__ import annotations

import ctypes
import os
import random
import struct
import zlib

import pytest
from fmpy.fmi1 import FMICallException

from railfmu.fmus.cosim.slave import Slave
from railfmu.models import all_models

MODELS = [m.identifier for m in all_models()]
PARAMS = {"TrackIrregularity": {"psd_level": 2, "seed": 3}}
SEED = int(os.environ.get("RAILFMU_FUZZ_SEED", "0"))
CASES = int(os.environ.get("RAILFMU_FUZZ_CASES", "60"))
H = 1e-3
WARMUP = 20
# the in-memory header (SnapshotHeader): magic, version, size, guid[64], identifier[64],
# checksum, strings_checksum
HEADER = struct.Struct("=IIQ64s64sII")


class Fmu:
    """One initialised instance, its saved state ``home`` at t = WARMUP H and the outputs one
    step later: after every refused call, restoring ``home`` and stepping must give them."""

    def __init__(self, fmu_dir, ident):
        self.ident = ident
        self.s = Slave(fmu_dir / f"{ident}.fmu", ident)
        self.s.initialize(0.0, None, PARAMS.get(ident, {}))
        for k in range(WARMUP):
            self.s.do_step(k * H, H)
        self.vrs = [v.valueReference for v in self.s.md.modelVariables if v.type == "Real"]
        self.home = self.s.fmu.getFMUstate()
        self.blob = bytes(self.s.fmu.serializeFMUstate(self.home))
        self.expected = self.step_from_home()

    def reals(self):
        return self.s.fmu.getReal(self.vrs)

    def step_from_home(self):
        self.s.fmu.setFMUstate(self.home)
        self.s.do_step(WARMUP * H, H)
        return self.reals()

    def assert_usable(self):
        before = len(self.s.messages)
        assert self.step_from_home() == self.expected  # bit-identical
        assert not self.s.messages[before:]

    def refused(self, call, *args, reason: str = ""):
        """call(*args) must fail with a logged error (containing ``reason``) and change no
        variable."""
        before, n = self.reals(), len(self.s.messages)
        with pytest.raises(FMICallException):
            call(*args)
        errors = [m for st, _, m in self.s.messages[n:] if st == "Error"]
        assert errors, "refused without a logged reason"
        assert reason in errors[-1], errors[-1]
        assert self.reals() == before
        return errors[-1]


@pytest.fixture(scope="module")
def fmus(fmu_dir):
    opened = {ident: Fmu(fmu_dir, ident) for ident in MODELS}
    yield opened
    for f in opened.values():
        f.s.fmu.freeFMUstate(f.home)
        f.s.close()


def rng_for(ident: str, kind: str) -> random.Random:
    return random.Random(f"{SEED} {ident} {kind}")


def with_crc(body: bytes) -> bytes:
    """A blob of body and a correct size word and CRC-32: a forgery only identity and layout
    checks can refuse."""
    body = body[:8] + struct.pack("=I", len(body) + 4) + body[12:]
    return body + struct.pack("=I", zlib.crc32(body))


@pytest.mark.parametrize("target", MODELS)
def test_states_of_every_other_fmu_are_refused(fmus, target):
    a = fmus[target]
    for ident, b in fmus.items():
        if ident == target:
            continue
        # in memory: checked by its header before its (differently sized) payload is read
        msg = a.refused(a.s.fmu.setFMUstate, b.home, reason="saved by another FMU")
        assert ident in msg and target in msg
        a.refused(a.s.fmu.serializeFMUstate, b.home, reason="another FMU")
        state = ctypes.c_void_p(b.home.value)
        a.refused(a.s.fmu.fmi2FreeFMUstate, a.s.fmu.component, ctypes.byref(state),
                  reason="another FMU")
        # serialized: intact (its CRC is right), so refused by identity
        a.refused(a.s.fmu.deSerializeFMUstate, b.blob, reason="another FMU")
    a.assert_usable()
    b = next(f for i, f in fmus.items() if i != target)
    b.assert_usable()  # the foreign state was left alone


@pytest.mark.parametrize("ident", MODELS)
def test_damaged_serialized_states_are_refused(fmus, ident):
    f = fmus[ident]
    blob, deser = f.blob, f.s.fmu.deSerializeFMUstate
    n = len(blob)
    reason = "fmi2DeSerializeFMUstate"
    rng = rng_for(ident, "random")
    for _ in range(CASES):
        junk = rng.randbytes(rng.randrange(0, 2 * n))
        f.refused(deser, junk, reason=reason)
        f.refused(deser, blob[:12] + junk, reason=reason)  # past magic, version and size word
    rng = rng_for(ident, "truncated")
    lengths = set(range(min(n, 64))) | set(range(max(0, n - 16), n))
    lengths |= {rng.randrange(n) for _ in range(CASES)}
    for k in sorted(lengths):
        f.refused(deser, blob[:k], reason=reason)
    f.refused(deser, blob + b"\0", reason=reason)
    rng = rng_for(ident, "flipped")
    positions = set(range(min(n, 256))) | {rng.randrange(n) for _ in range(CASES)}
    for i in sorted(positions):  # a single bit anywhere: CRC-32 catches every one
        damaged = bytearray(blob)
        damaged[i] ^= 1 << rng.randrange(8)
        f.refused(deser, bytes(damaged), reason=reason)
    for _ in range(CASES):  # a burst of up to 4 bytes: caught too (bursts <= 32 bits)
        damaged = bytearray(blob)
        i = rng.randrange(n - 4)
        for j in range(i, i + rng.randrange(1, 5)):
            damaged[j] ^= rng.randrange(1, 256)
        f.refused(deser, bytes(damaged), reason=reason)
    f.assert_usable()


@pytest.mark.parametrize("ident", MODELS)
def test_forged_serialized_states_never_crash(fmus, ident):
    """Right size word and CRC, bytes changed behind them: refused by the identity, count,
    state and string-length checks, or accepted as a state (whose payload is just numbers);
    never a read or write out of bounds (see `make sanitize`)."""
    f = fmus[ident]
    blob, rng = f.blob[:-4], rng_for(ident, "forged")
    for _ in range(CASES):
        damaged = bytearray(blob)
        for _ in range(rng.randrange(1, 4)):
            i = rng.randrange(len(damaged))
            damaged[i] = rng.randrange(256)
        if rng.random() < 0.3:  # a cut, or bytes added, at random
            cut = rng.randrange(12, len(damaged))
            damaged = damaged[:cut] + rng.randbytes(rng.randrange(0, 16))
        try:
            state = f.s.fmu.deSerializeFMUstate(with_crc(bytes(damaged)))
        except FMICallException:
            continue
        f.s.fmu.freeFMUstate(state)
    # the forgery of identity alone: another GUID with a valid CRC
    guid = f.s.md.guid.encode()
    i = blob.find(guid)
    other = blob[:i] + guid[:-2] + b"0}" + blob[i + len(guid):]
    if other != blob:
        f.refused(f.s.fmu.deSerializeFMUstate, with_crc(other), reason="GUID differs")
    f.assert_usable()


@pytest.mark.parametrize("ident", MODELS)
def test_damaged_states_in_memory_are_refused(fmus, ident):
    f = fmus[ident]
    state = f.s.fmu.getFMUstate()
    size = HEADER.unpack(ctypes.string_at(state.value, HEADER.size))[2]
    mem = (ctypes.c_ubyte * size).from_address(state.value)
    rng = rng_for(ident, "memory")
    positions = set(range(HEADER.size)) | {rng.randrange(HEADER.size, size) for _ in range(CASES)}
    for i in sorted(positions):
        bit = 1 << rng.randrange(8)
        mem[i] ^= bit
        try:
            f.refused(f.s.fmu.setFMUstate, state)
        finally:
            mem[i] ^= bit
    # random memory, with and without a valid-looking header in front
    junk = (ctypes.c_ubyte * size).from_buffer_copy(rng.randbytes(size))
    f.refused(f.s.fmu.setFMUstate, ctypes.c_void_p(ctypes.addressof(junk)),
              reason="not created by a railfmu FMU")
    head = bytearray(ctypes.string_at(state.value, HEADER.size - 8))
    ctypes.memmove(junk, bytes(head), len(head))
    f.refused(f.s.fmu.setFMUstate, ctypes.c_void_p(ctypes.addressof(junk)),
              reason="checksum mismatch")
    f.s.fmu.setFMUstate(state)  # undamaged again: accepted
    f.s.fmu.freeFMUstate(state)
    f.assert_usable()
