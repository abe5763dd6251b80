"""Light mutation probe: corrupt one payload byte of a valid vector, fix both CRCs, and record
which exceptions are not a spec error kind (places where the spec/this reader has no rule)."""
import collections, os, random, struct, sys, traceback
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import DlgsError, crc32c
import run_vectors as rv

VEC = rv.VEC
random.seed(int(sys.argv[1]) if len(sys.argv) > 1 else 1)
names = ["tiny-still", "tiny-3gop-zstd", "lod3-csog-compact", "lod3-csog-tiered", "lod3-residuals",
         "lod3-rdlt-predictive", "tiny-laed", "scaffold-ahac-tiny", "scaffold-tiny-residual", "lod3-dynamic-life"]
res = collections.Counter()
odd = collections.Counter()
for it in range(int(sys.argv[2]) if len(sys.argv) > 2 else 200):
    name = random.choice(names)
    d = bytearray(open(os.path.join(VEC, "valid", name + ".dlgs"), "rb").read())
    # list chunks
    chunks = []
    off = 12
    while off + 24 <= len(d):
        ln = struct.unpack_from("<Q", d, off + 12)[0]
        chunks.append((off, bytes(d[off:off + 4]), ln))
        off += 28 + ln
    off, t, ln = random.choice([c for c in chunks if c[2] > 0 and c[1] not in (b"TAIL",)])
    pos = off + 24 + random.randrange(min(ln, 64) if random.random() < 0.6 else ln)
    d[pos] ^= 1 << random.randrange(8)
    struct.pack_into("<I", d, off + 24 + ln, crc32c(d[off + 24:off + 24 + ln]))
    try:
        rv.full_decode(bytes(d), name)
        res[(t, "ok")] += 1
    except DlgsError as e:
        res[(t, e.kind)] += 1
    except Exception as e:
        tb = traceback.extract_tb(e.__traceback__)[-1]
        odd[(t, type(e).__name__, f"{os.path.basename(tb.filename)}:{tb.lineno}", str(e)[:60])] += 1
for k, v in sorted(res.items()):
    print(k, v)
print("--- non-spec exceptions")
for k, v in sorted(odd.items()):
    print(k, v)
