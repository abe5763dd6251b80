"""Damaged files raise the typed exception with the error's name, byte offset and message."""

import numpy as np
import pytest

import dlgs


def decode_all(blob):
    r = dlgs.open(blob)
    for g in range(r.info["gop_count"]):
        r.gop(g)
    r.frame(0.5)


def test_bad_magic_and_truncation(dyn_exact):
    blob = dyn_exact.read_bytes()
    with pytest.raises(dlgs.FormatError) as e:
        dlgs.open(b"\0" + blob[1:])
    assert (e.value.kind, e.value.name, e.value.offset) == ("Format", "BadMagic", 0)
    assert "magic" in e.value.message and isinstance(e.value, dlgs.DlgsError)
    with pytest.raises(dlgs.FormatError) as e:
        dlgs.open(blob[: len(blob) - 7])
    assert e.value.offset is not None and 0 <= e.value.offset <= len(blob)


def test_flipped_payload_byte_is_a_crc_error(dyn_exact):
    blob = bytearray(dyn_exact.read_bytes())
    i = len(blob) // 3
    blob[i] ^= 0x40
    with pytest.raises(dlgs.FormatError) as e:
        decode_all(bytes(blob))
    assert e.value.name == "PayloadCrc"
    # the offset is where the damage is detected (the chunk's CRC), after the byte
    assert i <= e.value.offset <= len(blob) and str(e.value.offset) in e.value.message


def test_random_damage_never_crashes(dyn_exact):
    blob = dyn_exact.read_bytes()
    rng = np.random.default_rng(7)
    raised = 0
    for _ in range(25):
        b = bytearray(blob)
        for p in rng.integers(0, len(b), 3):
            b[p] ^= int(rng.integers(1, 256))
        try:
            decode_all(bytes(b))
        except dlgs.DlgsError as e:
            assert e.kind in ("Format", "Limit") and e.message
            raised += 1
    assert raised >= 20


def test_requests_and_io(dyn_exact, work):
    r = dlgs.open(dyn_exact)
    with pytest.raises(dlgs.RequestError):
        r.frame(99.0)
    with pytest.raises(dlgs.RequestError):
        r.render(0.0, "not a camera")
    with pytest.raises(dlgs.DlgsIoError) as e:
        dlgs.open(work / "missing.dlgs")
    assert e.value.kind == "Io"
