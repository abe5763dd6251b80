"""Encode the 200 PLY frames into one keyframe-delta .4dgs with the fourdgs reference
library, decode every frame back out, write INRIA PLYs, and report bytes/timings.

usage: fdgs_run.py PROFILE ORDER OUTDIR [--keyframe-every N] [--no-ply]
  PROFILE: fine | default | coarse (fourdgs' error-bound profiles)
  ORDER:   row  -> gaussian id = row index in each frame (the data as given)
           nn   -> ids propagated frame to frame by nearest neighbour (scipy cKDTree)
"""
import sys, os, time, json, math, argparse
sys.path.insert(0, '/tmp/peers')
import numpy as np
from scipy.spatial import cKDTree
import fourdgs
from fourdgs.model import GaussianSet
from fourdgs.keyframe_delta_writer import Sample, KeyframeDeltaOptions
from fourdgs.keyframe_delta_file import write_sequence, decode_streamed, reconstruct_at
from fourdgs.validate import validate
from plyio import read_ply, write_ply

ap = argparse.ArgumentParser()
ap.add_argument('profile'); ap.add_argument('order'); ap.add_argument('outdir')
ap.add_argument('--keyframe-every', type=int, default=KeyframeDeltaOptions().keyframe_every)
ap.add_argument('--no-ply', action='store_true')
ap.add_argument('--repeat', type=int, default=1, help='time encode and decode this many times; report the median')
a = ap.parse_args()

FPS = 30.0; N = 200; SIGMA_T = 1000.0   # seconds: >> clip length, so the temporal marginal is 1 at every frame
C0 = 0.28209479177387814
os.makedirs(a.outdir, exist_ok=True)
rep = dict(profile=a.profile, order=a.order, keyframe_every=a.keyframe_every, fourdgs=fourdgs.__version__)

# ---- load source frames (not part of the codec timing)
t = time.perf_counter()
frames = [read_ply('/tmp/peers/ply/wave_%04d.ply' % (i + 1)) for i in range(N)]
rep['load_ply_s'] = time.perf_counter() - t

# ---- identities
t = time.perf_counter()
ids = []
nn_conflicts = 0; next_id = frames[0].shape[0]
for i, f in enumerate(frames):
    n = f.shape[0]
    if a.order == 'row' or i == 0:
        ids.append(np.arange(n, dtype=np.int64)); continue
    prev = frames[i - 1]
    pp = np.stack([prev['x'], prev['y'], prev['z']], 1).astype(np.float64)
    pc = np.stack([f['x'], f['y'], f['z']], 1).astype(np.float64)
    _, j = cKDTree(pp).query(pc)
    cur = ids[i - 1][j].copy()
    # a previous gaussian claimed twice: the first claimant keeps the id, others get fresh ids (births)
    _, first = np.unique(j, return_index=True)
    dup = np.ones(n, bool); dup[first] = False
    nn_conflicts += int(dup.sum())
    cur[dup] = np.arange(next_id, next_id + dup.sum()); next_id += int(dup.sum())
    ids.append(cur)
rep['id_s'] = time.perf_counter() - t
rep['nn_conflicts'] = nn_conflicts

# ---- samples
duration = N / FPS
def gset(f, t0):
    n = f.shape[0]
    pos = np.stack([f['x'], f['y'], f['z']], 1)
    scl = np.exp(np.stack([f['scale_0'], f['scale_1'], f['scale_2']], 1))
    rot = np.stack([f['rot_1'], f['rot_2'], f['rot_3'], f['rot_0']], 1).astype(np.float64)   # xyzw
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    rgb = np.clip(np.stack([f['f_dc_0'], f['f_dc_1'], f['f_dc_2']], 1) * C0 + 0.5, 0, 1)
    alpha = 1 / (1 + np.exp(-f['opacity'].astype(np.float64)))
    return GaussianSet(
        positions=pos.astype(np.float32), scales=scl.astype(np.float32), rotations=rot.astype(np.float32),
        colors=np.concatenate([rgb, alpha[:, None]], 1).astype(np.float32),
        motions=np.zeros((n, 3), np.float32), mu_t=np.full(n, t0, np.float32),
        sigma_t=np.full(n, SIGMA_T, np.float32),
        win_lo=np.zeros(n, np.float64), win_hi=np.full(n, duration, np.float64))

t = time.perf_counter()
samples = [Sample(t0=i / FPS, ids=ids[i], gaussians=gset(f, i / FPS)) for i, f in enumerate(frames)]
rep['build_samples_s'] = time.perf_counter() - t

# ---- encode (in-memory samples -> bytes -> file)
kd = KeyframeDeltaOptions(keyframe_every=a.keyframe_every)
path = os.path.join(a.outdir, 'wave.4dgs')
runs = []
for _ in range(a.repeat):
    t = time.perf_counter()
    blob = write_sequence(samples, duration, kd=kd, profile=a.profile)
    with open(path, 'wb') as fh:
        fh.write(blob)
    runs.append(time.perf_counter() - t)
rep['encode_s_runs'] = runs; rep['encode_s'] = float(np.median(runs))
rep['bytes'] = os.path.getsize(path)
rep['bytes_per_frame'] = rep['bytes'] / N

# ---- decode (read file, compose every chunk, reconstruct each frame at its own t0)
runs = []
for _ in range(a.repeat):
    t = time.perf_counter()
    with open(path, 'rb') as fh:
        data = fh.read()
    dec = decode_streamed(data)
    grids = dec.grids
    states = [reconstruct_at(c.state, grids, c.t0) for c in dec.chunks]
    runs.append(time.perf_counter() - t)
rep['decode_s_runs'] = runs; rep['decode_s'] = float(np.median(runs))
rep['chunks'] = len(dec.chunks)
rep['keyframes'] = sum(1 for c in dec.chunks if c.kind == 0)
rep['updates_per_delta_mean'] = float(np.mean([c.update_count for c in dec.chunks if c.kind == 1])) if rep['keyframes'] < N else 0.0
rep['bounds'] = dec.quantization.bounds
q = dec.quantization
rep['steps'] = dict(pos=q.step_pos, scale_log=q.step_scale_log, rot=q.step_rot, rgb=q.step_rgb, alpha=q.step_alpha)
assert len(states) == N

# ---- validate with the package's own validator
t = time.perf_counter()
v = validate(data)
rep['validate_ok'] = bool(v.ok); rep['validate_findings'] = [str(x) for x in v.findings][:5]
rep['validate_s'] = time.perf_counter() - t

# ---- errors vs source (by id) and PLY output
t = time.perf_counter()
maxerr = dict(pos=0.0, scale_log=0.0, rgb=0.0, alpha=0.0, rot_quat_component=0.0)
for i, (f, s) in enumerate(zip(frames, states)):
    assert s['ids'].shape[0] == f.shape[0], (i, s['ids'].shape, f.shape)
    # source row of each decoded id
    order = np.argsort(ids[i]); rows = order[np.searchsorted(ids[i][order], s['ids'])]
    src = f[rows]
    pos = np.stack([src['x'], src['y'], src['z']], 1)
    maxerr['pos'] = max(maxerr['pos'], float(np.abs(s['centers'] - pos).max()))
    sl = np.stack([src['scale_0'], src['scale_1'], src['scale_2']], 1)
    maxerr['scale_log'] = max(maxerr['scale_log'], float(np.abs(np.log(s['scales']) - sl).max()))
    rgb = np.clip(np.stack([src['f_dc_0'], src['f_dc_1'], src['f_dc_2']], 1) * C0 + 0.5, 0, 1)
    maxerr['rgb'] = max(maxerr['rgb'], float(np.abs(s['rgb'] - rgb).max()))
    al = 1 / (1 + np.exp(-src['opacity'].astype(np.float64)))
    maxerr['alpha'] = max(maxerr['alpha'], float(np.abs(s['opacity'] - al).max()))
    q = np.stack([src['rot_1'], src['rot_2'], src['rot_3'], src['rot_0']], 1).astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    sgn = np.sign(np.sum(q * s['rotations'], 1)); sgn[sgn == 0] = 1
    maxerr['rot_quat_component'] = max(maxerr['rot_quat_component'], float(np.abs(s['rotations'] - q * sgn[:, None]).max()))
    if not a.no_ply:
        op_ = np.clip(s['opacity'], 1e-7, 1 - 1e-7)
        r = s['rotations']
        write_ply(os.path.join(a.outdir, 'wave_%04d.ply' % (i + 1)), {
            'x': s['centers'][:, 0], 'y': s['centers'][:, 1], 'z': s['centers'][:, 2],
            'f_dc_0': (s['rgb'][:, 0] - 0.5) / C0, 'f_dc_1': (s['rgb'][:, 1] - 0.5) / C0, 'f_dc_2': (s['rgb'][:, 2] - 0.5) / C0,
            'opacity': np.log(op_ / (1 - op_)),
            'scale_0': np.log(s['scales'][:, 0]), 'scale_1': np.log(s['scales'][:, 1]), 'scale_2': np.log(s['scales'][:, 2]),
            'rot_0': r[:, 3], 'rot_1': r[:, 0], 'rot_2': r[:, 1], 'rot_3': r[:, 2]})
rep['max_abs_err'] = maxerr
rep['errors_and_ply_write_s'] = time.perf_counter() - t
json.dump(rep, open(os.path.join(a.outdir, 'report.json'), 'w'), indent=1, default=str)
print(json.dumps(rep, indent=1, default=str))
