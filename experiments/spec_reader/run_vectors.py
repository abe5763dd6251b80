"""Run every conformance vector of format-spec/vectors with the spec-only reader."""
import os
import sys
import time
import traceback

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import DlgsError  # noqa: E402
from container import Container  # noqa: E402

VEC = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../format-spec/vectors"))


def load_expected():
    exp = {}
    for line in open(os.path.join(VEC, "expected.txt")):
        if line.startswith("#") or not line.strip():
            continue
        name, g, sha = line.split()
        exp.setdefault(name, {})[int(g)] = sha
    errs = {}
    for fn in ("expected-errors.txt", "expected-scaffold.txt"):
        for line in open(os.path.join(VEC, fn)):
            if line.startswith("#") or not line.strip():
                continue
            parts = line.split()
            errs[parts[0]] = parts[1]
    return exp, errs


def full_decode(data, name):
    """Decode everything decodable; raise DlgsError on the first fault."""
    c = Container(data)
    h = c.head
    notes = []
    if h.variant == 0:
        from dec3dgs import Decoder3DGS
        d = Decoder3DGS(c)
        shas = {}
        for g in range(h.gop_count):
            shas[g] = d.state(g).sha()
            if h.n_dynamic:
                from dynamic import gop_dynamic
                gop_dynamic(d, g)  # parse TFEA/MLPW/LIFE of every GOP
        laed = None
        ch, p = c.scene_payload(b"LAED")
        if ch is not None:
            from laed import parse_laed
            laed = parse_laed(p, ch.poff, h)
        return ("3dgs", d, shas, laed)
    else:
        from scaffold import ScaffoldDecoder
        d = ScaffoldDecoder(c)
        d.check_all()
        return ("scaffold", d, None, None)


def main(only=None):
    exp, errs = load_expected()
    rows = []
    for sub in ("valid", "invalid"):
        for fn in sorted(os.listdir(os.path.join(VEC, sub))):
            if not fn.endswith(".dlgs"):
                continue
            name = fn[:-5]
            if only and not any(o in name for o in only):
                continue
            data = open(os.path.join(VEC, sub, fn), "rb").read()
            t0 = time.time()
            res = run_one(sub, name, data, exp, errs)
            dt = time.time() - t0
            rows.append((name, res, dt))
            print(f"{name:32s} {dt:6.1f}s  {res}", flush=True)
    return rows


def run_one(sub, name, data, exp, errs):
    try:
        kind, d, shas, laed = full_decode(data, name)
    except DlgsError as e:
        if sub == "invalid":
            want = errs.get(name)
            ok = "MATCH" if want == e.kind else f"MISMATCH (want {want})"
            return f"error {e.kind} @{e.offset} [{e.msg}] -> {ok}"
        return f"UNEXPECTED ERROR {e.kind} @{e.offset}: {e.msg}"
    except NotImplementedError as e:
        return f"NOT IMPLEMENTED: {e}"
    except Exception as e:  # noqa
        traceback.print_exc()
        return f"CRASH {type(e).__name__}: {e}"
    if sub == "invalid":
        return f"NO ERROR (want {errs.get(name)}) -> MISMATCH"
    out = []
    if kind == "3dgs":
        want = exp.get(name, {})
        good = sum(1 for g, s in shas.items() if want.get(g) == s)
        out.append(f"sha {good}/{len(want)} GOPs match" if want else "no sha listed")
        if good != len(want):
            out.append("got " + " ".join(f"{g}:{s[:12]}" for g, s in shas.items()))
        fpath = os.path.join(VEC, "valid", name + ".frames.f32")
        if os.path.exists(fpath):
            from dynamic import compare_frames
            out.append(compare_frames(d, fpath))
        epath = os.path.join(VEC, "valid", name + ".embeddings.f32")
        if os.path.exists(epath):
            from laed import compare_embeddings
            out.append(compare_embeddings(d, laed, epath))
    else:
        fpath = os.path.join(VEC, "valid", name + ".frames.f32")
        from scaffold import compare_frames as scf
        out.append(scf(d, fpath))
    return "; ".join(out)




def report_cover():
    from common import COVER
    for k, v in sorted(COVER.items()):
        print(f"  cover: {k}: {v}")


if __name__ == "__main__":
    main(sys.argv[1:] or None)
    report_cover()
