"""The `.4dgs` keyframe-delta peer (the `fourdgs` reference library from PyPI) on a folder of
per-frame PLYs (SH 0 colour is what .4dgs stores) with known identities (frame_NNNN.ids from
`dlgs synth-frames --ids`: the peer's best case, correspondence given).

usage: fdgs_sequence.py FRAMES_DIR OUT_DIR PROFILE [--fps 30]
Writes OUT_DIR/seq.4dgs and every decoded frame as OUT_DIR/frame_NNNN.ply; prints one JSON line
(bytes, bytes_per_frame, encode_s, decode_s).
"""
import argparse, glob, json, os, time

import numpy as np
from fourdgs.model import GaussianSet
from fourdgs.keyframe_delta_writer import Sample, KeyframeDeltaOptions
from fourdgs.keyframe_delta_file import write_sequence, decode_streamed, reconstruct_at

C0 = 0.28209479177387814
NAMES = ['x', 'y', 'z', 'f_dc_0', 'f_dc_1', 'f_dc_2', 'opacity', 'scale_0', 'scale_1', 'scale_2',
         'rot_0', 'rot_1', 'rot_2', 'rot_3']


def read_ply(path):
    raw = open(path, 'rb').read()
    end = raw.find(b'end_header')
    start = raw.index(b'\n', end) + 1
    n, props = 0, []
    for line in raw[:end].decode().splitlines():
        p = line.split()
        if p[:2] == ['element', 'vertex']:
            n = int(p[2])
        elif p and p[0] == 'property':
            props.append(p[2])
    return np.frombuffer(raw, dtype=np.dtype([(k, '<f4') for k in props]), count=n, offset=start)


def write_ply(path, cols):
    n = len(cols['x'])
    a = np.empty(n, dtype=np.dtype([(k, '<f4') for k in NAMES]))
    for k in NAMES:
        a[k] = cols[k]
    hdr = 'ply\nformat binary_little_endian 1.0\nelement vertex %d\n' % n
    hdr += ''.join('property float %s\n' % k for k in NAMES) + 'end_header\n'
    with open(path, 'wb') as f:
        f.write(hdr.encode())
        f.write(a.tobytes())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('frames')
    ap.add_argument('out')
    ap.add_argument('profile')
    ap.add_argument('--fps', type=float, default=30.0)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    plys = sorted(glob.glob(os.path.join(a.frames, 'frame_*.ply')))
    frames = [read_ply(p) for p in plys]
    ids = [np.fromfile(p[:-4] + '.ids', dtype='<u4').astype(np.int64) for p in plys]
    n_frames = len(frames)
    duration = n_frames / a.fps

    def gset(f, t0):
        n = f.shape[0]
        rot = np.stack([f['rot_1'], f['rot_2'], f['rot_3'], f['rot_0']], 1).astype(np.float64)
        rot /= np.maximum(np.linalg.norm(rot, axis=1, keepdims=True), 1e-12)
        rgb = np.clip(np.stack([f['f_dc_0'], f['f_dc_1'], f['f_dc_2']], 1) * C0 + 0.5, 0, 1)
        alpha = 1 / (1 + np.exp(-f['opacity'].astype(np.float64)))
        return GaussianSet(
            positions=np.stack([f['x'], f['y'], f['z']], 1).astype(np.float32),
            scales=np.exp(np.stack([f['scale_0'], f['scale_1'], f['scale_2']], 1)).astype(np.float32),
            rotations=rot.astype(np.float32),
            colors=np.concatenate([rgb, alpha[:, None]], 1).astype(np.float32),
            motions=np.zeros((n, 3), np.float32), mu_t=np.full(n, t0, np.float32),
            sigma_t=np.full(n, 1000.0, np.float32),
            win_lo=np.zeros(n, np.float64), win_hi=np.full(n, duration, np.float64))

    samples = [Sample(t0=i / a.fps, ids=ids[i], gaussians=gset(f, i / a.fps))
               for i, f in enumerate(frames)]
    t = time.perf_counter()
    blob = write_sequence(samples, duration, kd=KeyframeDeltaOptions(), profile=a.profile)
    encode_s = time.perf_counter() - t
    path = os.path.join(a.out, 'seq.4dgs')
    with open(path, 'wb') as fh:
        fh.write(blob)
    t = time.perf_counter()
    dec = decode_streamed(open(path, 'rb').read())
    states = [reconstruct_at(c.state, dec.grids, c.t0) for c in dec.chunks]
    decode_s = time.perf_counter() - t
    assert len(states) == n_frames, (len(states), n_frames)
    for i, s in enumerate(states):
        c, q = s['centers'], s['rotations']
        rgb = np.clip(s['rgb'], 0, 1)
        op = np.clip(s['opacity'], 1e-7, 1 - 1e-7)
        sl = np.log(np.maximum(s['scales'], 1e-30))
        write_ply(os.path.join(a.out, 'frame_%04d.ply' % i), {
            'x': c[:, 0], 'y': c[:, 1], 'z': c[:, 2],
            'f_dc_0': (rgb[:, 0] - 0.5) / C0, 'f_dc_1': (rgb[:, 1] - 0.5) / C0,
            'f_dc_2': (rgb[:, 2] - 0.5) / C0, 'opacity': np.log(op / (1 - op)),
            'scale_0': sl[:, 0], 'scale_1': sl[:, 1], 'scale_2': sl[:, 2],
            'rot_0': q[:, 3], 'rot_1': q[:, 0], 'rot_2': q[:, 1], 'rot_3': q[:, 2]})
    size = os.path.getsize(path)
    print(json.dumps(dict(bytes=size, bytes_per_frame=size / n_frames, encode_s=encode_s,
                          decode_s=decode_s, frames=n_frames)))


if __name__ == '__main__':
    main()
