"""Build the results table (markdown) from the measurements under /tmp/peers."""
import csv, json, os, glob
R = '/tmp/peers'
def psnr_stats(path):
    if not os.path.exists(path): return None
    rows = [r for r in csv.DictReader(open(path)) if r['psnr'] not in ('ERR', '')]
    if not rows: return None
    p = [(float(r['psnr']), int(r['frame'])) for r in rows]
    return sum(x for x, _ in p) / len(p), min(p), len(p)
def kv(path):
    return {l.split()[0]: l.split()[1] for l in open(path) if l.strip()}
def cells(st):
    return f'{st[0]:.2f} | {st[1][0]:.2f} ({st[1][1]}) | {st[2]}' if st else 'n/a | n/a | 0'
out = ['| codec | setting | total bytes | bytes/frame | mean PSNR (dB) | worst PSNR (dB, frame) | frames scored | encode s | decode s |',
       '|---|---|---:|---:|---:|---:|---:|---:|---:|']
enc = kv(f'{R}/res/spz_times.txt')
st = psnr_stats(f'{R}/res/psnr_spz_v3.csv')
for v in ('4', '3'):
    total = sum(os.path.getsize(f) for f in glob.glob(f'{R}/spz_v{v}/*.spz'))
    setting = 'SPZ v4 (tool default), one file per frame [PSNR: see note a]' if v == '4' else 'SPZ v3 (--spz-version 3), one file per frame'
    out.append(f"| SPZ via splat-transform | {setting} | {total:,} | {total/200:,.0f} | {cells(st)} | {float(enc['encode_v'+v]):.1f} | {float(enc['decode_v'+v]):.1f} |")
for prof in ('fine', 'default', 'coarse'):
    for order in ('row', 'nn'):
        d = f'{R}/fdgs/{prof}_{order}'
        if not os.path.exists(f'{d}/report.json'): continue
        rep = json.load(open(f'{d}/report.json'))
        full = psnr_stats(f'{R}/res/psnr_fdgs_{prof}_{order}.csv')
        st = full or psnr_stats(f'{R}/res/psnr10_fdgs_{prof}_{order}.csv')
        lab = {'row': 'ids = row index (order as given)', 'nn': 'ids chained by nearest neighbour'}[order]
        out.append(f"| .4dgs keyframe-delta (fourdgs) | profile `{prof}`{' (default)' if prof=='default' else ''}, {lab}, keyframe every {rep['keyframe_every']} | {rep['bytes']:,} | {rep['bytes_per_frame']:,.0f} | {cells(st)} | {rep['encode_s']:.2f} | {rep['decode_s']:.2f} |")
d = f'{R}/fdgs/birth_default'
if os.path.exists(f'{d}/report.json'):
    rep = json.load(open(f'{d}/report.json')); enc_b = kv(f'{d}/encode_time.txt')
    st = psnr_stats(f'{R}/res/psnr10_fdgs_birth_default.csv')
    out.append(f"| .4dgs gaussian-birth (extra: `fourdgs convert` CLI) | profile `default`, velocities from row-order frame differences [note e] | {rep['bytes']:,} | {rep['bytes']/200:,.0f} | {cells(st)} | {float(enc_b['encode_s']):.2f} | {rep['decode_s']:.2f} |")
print('\n'.join(out))
