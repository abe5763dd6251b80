"""Extra: the fourdgs CLI's own PLY-sequence converter (`fourdgs convert DIR`), which writes the
`gaussian-birth` temporal model (not keyframe-delta). Decode: fourdgs.read() + GaussianSet.state_at(t)
at each frame's slot centre t = (i + 0.5) / 30, written as INRIA PLY.
usage: fdgs_birth.py OUTDIR   (expects OUTDIR/wave.4dgs made by `fourdgs convert`)"""
import sys, os, time, json
sys.path.insert(0, '/tmp/peers')
import numpy as np, fourdgs
from plyio import write_ply
C0 = 0.28209479177387814; FPS = 30.0; N = 200
out = sys.argv[1]; path = os.path.join(out, 'wave.4dgs')
t = time.perf_counter()
scene = fourdgs.read(path)
g = scene.gaussians
states = [g.state_at((i + 0.5) / FPS, scene.header.cutoff) for i in range(N)]
dec_s = time.perf_counter() - t
counts = [len(s['indices']) for s in states]
for i, s in enumerate(states):
    idx = s['indices']; c = s['centers']; r = s['orientations']          # xyzw
    rgb = g.colors[idx, :3].astype(np.float64); op_ = np.clip(s['opacity'], 1e-7, 1 - 1e-7)
    sc = np.log(g.scales[idx].astype(np.float64))
    write_ply(os.path.join(out, 'wave_%04d.ply' % (i + 1)), {
        'x': c[:, 0], 'y': c[:, 1], 'z': c[:, 2],
        'f_dc_0': (rgb[:, 0] - .5) / C0, 'f_dc_1': (rgb[:, 1] - .5) / C0, 'f_dc_2': (rgb[:, 2] - .5) / C0,
        'opacity': np.log(op_ / (1 - op_)), 'scale_0': sc[:, 0], 'scale_1': sc[:, 1], 'scale_2': sc[:, 2],
        'rot_0': r[:, 3], 'rot_1': r[:, 0], 'rot_2': r[:, 1], 'rot_3': r[:, 2]})
rep = dict(bytes=os.path.getsize(path), decode_s=dec_s, visible_min=min(counts), visible_max=max(counts),
           total=g.count, temporal_model=scene.header.temporal_model,
           max_abs_motion=float(np.abs(g.motions).max()), median_abs_motion=float(np.median(np.abs(g.motions))))
json.dump(rep, open(os.path.join(out, 'report.json'), 'w'), indent=1); print(json.dumps(rep, indent=1))
