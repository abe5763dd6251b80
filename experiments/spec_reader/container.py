"""Random-access container reader (§2-§5, §3.3 rules, §8)."""
import struct

from common import DlgsError, Reader, crc32c

MAGIC = b"\x89DLGS\r\n\x1a"
SCENE = 0xFFFFFFFF
NOREF = 0xFFFFFFFF

LIMIT_PAYLOAD = 4 << 30
LIMIT_GOPS = 1048576
LIMIT_GAUSS = 67108864
LIMIT_SCENE_CHUNKS = 4096
LIMIT_GOP_CHUNKS = 4096

KNOWN = {b"HEAD", b"META", b"GOPH", b"CRAW", b"TFEA", b"MLPW", b"CSOG", b"RNTC", b"RDLT",
         b"LAED", b"ANCR", b"AMLP", b"ADEF", b"AHAC", b"LIFE", b"GIDX", b"TAIL"}
GOP_LEVEL = {b"CRAW", b"TFEA", b"MLPW", b"CSOG", b"RNTC", b"RDLT", b"ANCR", b"AMLP", b"ADEF",
             b"AHAC", b"LIFE"}
SCENE_LEVEL_TYPES = {b"META", b"LAED"}
ALPHABET = set(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789 ")


class Chunk:
    def __init__(self, off, ctype, flags, gop, length):
        self.off = off
        self.type = ctype
        self.flags = flags
        self.gop = gop
        self.length = length
        self.poff = off + 24
        self.end = off + 28 + length

    def __repr__(self):
        return f"<{self.type.decode(errors='replace')} @{self.off} gop={self.gop:#x} len={self.length}>"


def read_header(data, off, region_end):
    """§3.1 steps 1-4."""
    if off + 24 > region_end or off + 24 > len(data):
        raise DlgsError("Truncated", off, "chunk header")
    h = data[off:off + 24]
    if crc32c(h[:20]) != struct.unpack_from("<I", h, 20)[0]:
        raise DlgsError("HeaderCrc", off, "header CRC")
    ctype = bytes(h[0:4])
    if any(b not in ALPHABET for b in ctype):
        raise DlgsError("InvalidChunkType", off, repr(ctype))
    flags, _res, gop, length = struct.unpack_from("<HHIQ", h, 4)
    if length > LIMIT_PAYLOAD:
        raise DlgsError("LimitExceeded", off, f"{ctype} length {length}")
    if off + 28 + length > region_end:
        raise DlgsError("Truncated", off, f"{ctype} payload past region end")
    return Chunk(off, ctype, flags, gop, length)


def read_payload(data, ch):
    p = data[ch.poff:ch.poff + ch.length]
    crc = struct.unpack_from("<I", data, ch.poff + ch.length)[0]
    if crc32c(p) != crc:
        raise DlgsError("PayloadCrc", ch.poff + ch.length, f"{ch.type} payload CRC")
    return bytes(p)


class Head:
    pass


def parse_head(p, base):
    r = Reader(p, base, "HEAD")
    if len(p) < 64:
        raise DlgsError("Truncated", base, "HEAD payload < 64")
    h = Head()
    (h.variant, h.residual_mode, h.sh_degree, h.lang_levels, h.lang_dims, h.time_channels,
     h.deform_model, _r) = struct.unpack_from("<8B", p, 0)
    (h.fps_num, h.fps_den, h.gop_length, h.key_interval, h.gop_count, h.frame_count,
     h.n_static, h.n_dynamic, h.refresh_interval) = struct.unpack_from("<9I", p, 8)

    def bad(field, off):
        raise DlgsError("InvalidField", base + off, f"HEAD.{field}")
    # Checks in field (offset) order: GUESS of the order (spec gives no order among fields).
    if h.variant not in (0, 1):
        bad("variant", 0)
    if h.residual_mode not in (0, 1, 2):
        bad("residual_mode", 1)
    if h.sh_degree > 3:
        bad("sh_degree", 2)
    if h.lang_levels > 8:
        bad("lang_levels", 3)
    if h.lang_dims > 16 or ((h.lang_dims == 0) != (h.lang_levels == 0)):
        bad("lang_dims", 4)
    if h.time_channels > 64 or ((h.time_channels == 0) != (h.n_dynamic == 0)):
        bad("time_channels", 5)
    if h.deform_model not in (0, 1):
        bad("deform_model", 6)
    if h.fps_num == 0:
        bad("fps_num", 8)
    if h.fps_den == 0:
        bad("fps_den", 12)
    if not 1 <= h.gop_length <= 65536:
        bad("gop_length", 16)
    if not (1 <= h.key_interval <= h.gop_length and h.gop_length % h.key_interval == 0):
        bad("key_interval", 20)
    if h.gop_count < 1:
        bad("gop_count", 24)
    if h.gop_count > LIMIT_GOPS:
        raise DlgsError("LimitExceeded", base + 24, "gop_count")
    if not ((h.gop_count - 1) * h.gop_length < h.frame_count <= h.gop_count * h.gop_length):
        bad("frame_count", 28)
    if h.n_static + h.n_dynamic > LIMIT_GAUSS:
        raise DlgsError("LimitExceeded", base + 32, "n_static + n_dynamic")
    ri = h.refresh_interval
    if ri != 0 and (ri == 1 or h.residual_mode != 1):
        bad("refresh_interval", 40)
    h.L = h.lang_levels * h.lang_dims
    h.K = h.gop_length // h.key_interval + 1
    return h


def goph_expect(h, g):
    first = g * h.gop_length
    fc = min(h.gop_length, h.frame_count - first)
    if g == 0 or h.residual_mode == 0 or (h.residual_mode == 1 and h.refresh_interval > 0 and g % h.refresh_interval == 0):
        ref = NOREF
    elif h.residual_mode == 1:
        ref = g - 1
    else:
        ref = 0
    return first, fc, ref


def use_rank(h, ctype, has_ref):
    """§3.3 table: returns rank int, 'ignored', or None for '—'."""
    dyn = h.n_dynamic > 0
    if h.variant == 0:
        t = {
            b"CRAW": None if has_ref else 0, b"CSOG": None if has_ref else 0,
            b"RNTC": 0 if has_ref else None, b"RDLT": 0 if has_ref else None,
            b"TFEA": 1 if dyn else None, b"MLPW": 2 if dyn else None, b"LIFE": 3 if dyn else None,
            b"ANCR": None, b"AHAC": None, b"AMLP": None, b"ADEF": None,
        }
    else:
        t = {
            b"CRAW": "ignored", b"CSOG": "ignored",
            b"RNTC": 0 if has_ref else "ignored", b"RDLT": "ignored",
            b"TFEA": 3 if dyn else None, b"MLPW": "ignored", b"LIFE": None,
            b"ANCR": None if has_ref else 0, b"AHAC": None if has_ref else 0,
            b"AMLP": 1, b"ADEF": 2 if dyn else None,
        }
    return t.get(ctype)


class Container:
    def __init__(self, data):
        self.data = data
        self.open()

    def open(self):
        d = self.data
        if len(d) < 12:
            # GUESS: a file shorter than the signature; BadMagic if the bytes present differ
            if d[:len(d)] != MAGIC[:len(d)]:
                raise DlgsError("BadMagic", 0, "magic")
            raise DlgsError("Truncated", 0, "signature")
        if d[:8] != MAGIC:
            raise DlgsError("BadMagic", 0, "magic")
        major, minor = struct.unpack_from("<HH", d, 8)
        if major != 1:
            raise DlgsError("UnsupportedVersion", 8, f"major {major}")
        self.minor = minor
        head = read_header(d, 12, len(d))
        if head.type != b"HEAD" or head.gop != SCENE:
            raise DlgsError("Order", 12, "first chunk is not a scene-level HEAD")  # GUESS kind
        self.head_chunk = head
        self.head = parse_head(read_payload(d, head), head.poff)
        h = self.head
        # §5.3 TAIL
        head_end = head.end
        if len(d) < head_end + 36:
            raise DlgsError("Truncated", len(d), "file shorter than HEAD + TAIL")
        toff = len(d) - 36
        try:
            tail = read_header(d, toff, len(d))
            if tail.type != b"TAIL" or tail.gop != SCENE or tail.length != 8:
                raise DlgsError("MissingChunk", toff, "TAIL")
            tp = read_payload(d, tail)
        except DlgsError as e:
            raise DlgsError("MissingChunk", toff, f"TAIL ({e.kind})")
        gidx_off = struct.unpack("<Q", tp)[0]
        if gidx_off < head_end or gidx_off >= toff:
            raise DlgsError("Index", tail.poff, "gidx_offset")
        gidx = read_header(d, gidx_off, toff)
        if gidx.type != b"GIDX" or gidx.gop != SCENE:
            raise DlgsError("MissingChunk", gidx_off, "GIDX")
        if gidx.end != toff:
            raise DlgsError("Order", gidx_off, "GIDX does not end at TAIL")
        self.gidx = gidx
        # scene-level chunk walk (§5.2)
        self.scene_chunks = []
        off = head_end
        while True:
            if off >= gidx_off:
                raise DlgsError("Truncated", off, "no GOPH before GIDX")
            ch = read_header(d, off, gidx_off)
            if ch.type == b"GOPH":
                break
            self.check_scene_chunk(ch)
            self.scene_chunks.append(ch)
            if len(self.scene_chunks) > LIMIT_SCENE_CHUNKS:
                raise DlgsError("LimitExceeded", off, "scene-level chunks")
            off = ch.end
        gop0 = off
        # GIDX payload
        gp = read_payload(d, gidx)
        base = gidx.poff
        if len(gp) < 4:
            raise DlgsError("Truncated", base, "GIDX")
        cnt = struct.unpack_from("<I", gp, 0)[0]
        if cnt != h.gop_count:
            raise DlgsError("InvalidField", base, "GIDX entry_count")
        if len(gp) < 4 + 32 * cnt:
            raise DlgsError("Truncated", base, "GIDX entries")
        self.entries = []
        prev_end = gop0
        for i in range(cnt):
            eo = 4 + 32 * i
            g, ff, fc, ref, o, ln = struct.unpack_from("<IIIIQQ", gp, eo)
            if g != i:
                raise DlgsError("Index", base + eo, "GIDX gop")
            eff, efc, eref = goph_expect(h, i)
            if ff != eff:
                raise DlgsError("InvalidField", base + eo + 4, "GIDX first_frame")
            if fc != efc:
                raise DlgsError("InvalidField", base + eo + 8, "GIDX frame_count")
            if ref != eref:
                raise DlgsError("InvalidField", base + eo + 12, "GIDX reference_gop")
            if o != prev_end:
                raise DlgsError("Index", base + eo + 16, "GIDX offset")
            if o + ln > gidx_off:
                raise DlgsError("Index", base + eo + 24, "GIDX length")
            self.entries.append((o, ln, ref))
            prev_end = o + ln
        if prev_end != gidx_off:
            raise DlgsError("Index", base, "GIDX does not end at GIDX")
        self._gops = {}

    def check_scene_chunk(self, ch):
        t = ch.type
        if ch.gop != SCENE:
            raise DlgsError("Order", ch.off, f"{t} with gop {ch.gop} among scene-level chunks")
        if t in (b"HEAD", b"GIDX", b"TAIL"):
            raise DlgsError("Order", ch.off, f"{t} among scene-level chunks")
        if t not in KNOWN:
            if ch.flags & 1:
                raise DlgsError("UnknownCriticalChunk", ch.off, repr(t))
            return
        if t in GOP_LEVEL:
            raise DlgsError("Order", ch.off, f"GOP-level {t} at scene level")

    def scene_payload(self, ctype):
        for ch in self.scene_chunks:
            if ch.type == ctype:
                return ch, read_payload(self.data, ch)
        return None, None

    def gop(self, g):
        """Chunk headers of GOP g, checked (§3.3, §5.1). Returns (goph fields, dict type->Chunk)."""
        if g in self._gops:
            return self._gops[g]
        d = self.data
        h = self.head
        o, ln, _ = self.entries[g]
        end = o + ln
        gh = read_header(d, o, end)
        if gh.type != b"GOPH" or gh.gop != g:
            raise DlgsError("Index", o, "GIDX offset does not hold this GOP's GOPH")
        gp = read_payload(d, gh)
        if len(gp) < 16:
            raise DlgsError("Truncated", gh.poff, "GOPH")  # GUESS kind for a short GOPH
        ff, fc, ref, _fl = struct.unpack_from("<IIII", gp, 0)
        eff, efc, eref = goph_expect(h, g)
        if ff != eff:
            raise DlgsError("InvalidField", gh.poff, "GOPH first_frame")
        if fc != efc:
            raise DlgsError("InvalidField", gh.poff + 4, "GOPH frame_count")
        if ref != eref:
            raise DlgsError("InvalidField", gh.poff + 8, "GOPH reference_gop")
        has_ref = ref != NOREF
        chunks = {}
        seen_rank = -1
        off = gh.end
        count = 0
        while off < end:
            ch = read_header(d, off, end)
            off = ch.end
            count += 1
            if count > LIMIT_GOP_CHUNKS:
                raise DlgsError("LimitExceeded", ch.off, "chunks per GOP")
            t = ch.type
            if t not in KNOWN:
                if ch.flags & 1:
                    raise DlgsError("UnknownCriticalChunk", ch.off, repr(t))
                continue
            if ch.gop != g:
                raise DlgsError("Order", ch.off, f"{t} gop field {ch.gop} in GOP {g}")  # GUESS
            if t in SCENE_LEVEL_TYPES or t in (b"HEAD", b"GOPH", b"GIDX", b"TAIL"):
                raise DlgsError("Order", ch.off, f"{t} inside GOP {g}")
            rank = use_rank(h, t, has_ref)
            if rank is None:
                raise DlgsError("Order", ch.off, f"{t} not usable in this GOP")
            if rank == "ignored":
                continue
            kind = b"RES" if t in (b"RNTC", b"RDLT") else t
            if kind in chunks:
                raise DlgsError("Order", ch.off, f"second {t} in GOP {g}")
            if rank < seen_rank:
                raise DlgsError("Order", ch.off, f"{t} after a chunk it must precede")
            seen_rank = rank
            chunks[kind] = ch
        # required chunks
        if h.variant == 0:
            if not has_ref:
                if b"CRAW" not in chunks and b"CSOG" not in chunks:
                    raise DlgsError("MissingChunk", o, "CRAW")
            else:
                if b"RES" not in chunks:
                    raise DlgsError("MissingChunk", o, "RDLT")
            if h.n_dynamic > 0:
                if b"TFEA" not in chunks:
                    raise DlgsError("MissingChunk", o, "TFEA")
                if b"MLPW" not in chunks:
                    raise DlgsError("MissingChunk", o, "MLPW")
        else:
            if not has_ref:
                if b"ANCR" in chunks and b"AHAC" in chunks:
                    raise DlgsError("Payload", chunks[b"AHAC"].off, "both ANCR and AHAC")
                if b"ANCR" not in chunks and b"AHAC" not in chunks:
                    raise DlgsError("MissingChunk", o, "ANCR")
                if b"AMLP" not in chunks:
                    raise DlgsError("MissingChunk", o, "AMLP")
            else:
                if b"RES" not in chunks:
                    raise DlgsError("MissingChunk", o, "RNTC")
            if h.n_dynamic > 0:
                if b"ADEF" not in chunks:
                    raise DlgsError("MissingChunk", o, "ADEF")
                if b"TFEA" not in chunks:
                    raise DlgsError("MissingChunk", o, "TFEA")
        res = ((ff, fc, ref), chunks)
        self._gops[g] = res
        return res

    def payload(self, ch):
        return read_payload(self.data, ch)
