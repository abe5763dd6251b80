"""Encode a real scene from numpy arrays as a dynamic .dlgs, then query it with text.

What a training script does at the end of a GOP, on a real scene with SYNTHETIC motion and
language (no trained DLGStream model or CLIP model is available here):

1. the real fruit scene (../shared/data) labelled by `dlgs labels` from its real per-Gaussian
   annotations: a 9-dim language feature per Gaussian, the language decoder and negatives;
2. arrays split into a static and a dynamic set, key time features (N_dyn, K, 16) and
   bias-free decoder weights made with numpy (a model's tensors would go here);
3. `dlgs.Writer` writes two GOPs; `dlgs.open` reads them back;
4. a text query (the embedding of category 4) at several times: relevance maps and masks.

Usage: python encode_and_query.py LABELLED_DIR OUT.dlgs
(LABELLED_DIR from `dlgs labels SCENE.ply --annotations A.json -o LABELLED_DIR`).
"""

import sys
from pathlib import Path

import numpy as np

import dlgs


def decoders(rng, hidden=16, scale=0.05, coeffs=1):
    """Bias-free MLPs (PyTorch (out, in) layout) with the routing of format-spec §6.4."""
    def mlp(inputs, outputs):
        return [rng.normal(0, scale, (hidden, inputs)).astype(np.float32),
                rng.normal(0, scale, (outputs, hidden)).astype(np.float32)]
    return {"deform": mlp(12, 6), "cov": mlp(12, 7), "opacity": mlp(12, 2),
            "color": mlp(12, 3 * coeffs), "lang": mlp(8, 9)}


def time_features(n, keys, gop, rng):
    """Smooth key features: one phase per Gaussian and channel, advancing with the key."""
    phase = rng.uniform(0, 2 * np.pi, (n, 1, 16))
    k = np.arange(keys, dtype=np.float64).reshape(1, keys, 1) + gop * (keys - 1)
    return (0.8 * np.sin(phase + 0.4 * k)).astype(np.float32)


def main(labelled: Path, out: Path) -> None:
    scene = dlgs.read_scene(labelled / "scene.ply")
    n = scene["positions"].shape[0]
    # The Gaussians above the median height move; the rest stay.
    moving = scene["positions"][:, 1] < np.median(scene["positions"][:, 1])
    static = {k: v[~moving] for k, v in scene.items()}
    dynamic = {k: v[moving] for k, v in scene.items()}
    rng = np.random.default_rng(53)
    gop_length, key_interval, gops = 30, 10, 2
    keys = gop_length // key_interval + 1
    with dlgs.Writer(out, fps=30, gop_length=gop_length, crf=6,
                     lang_decoder=labelled / "lang_decoder.safetensors",
                     negatives=np.load(labelled / "negatives.npy"),
                     progress=lambda d, t: print(f"  GOP {d}/{t} encoded")) as w:
        for g in range(gops):
            w.write_gop(static, dynamic, time_features(int(moving.sum()), keys, g, rng),
                        decoders(rng))
    r = dlgs.open(out)
    info = r.info
    print(f"{out}: {out.stat().st_size} bytes, {info['frame_count']} frames, "
          f"{info['n_static']} static + {info['n_dynamic']} dynamic of {n} Gaussians")

    query = np.load(labelled / "category_4.npy").reshape(-1)  # one embedding (D,)
    cam = r.cameras(count=8, width=320, height=240)[0]
    for t in (0.0, 0.5, 1.5):
        a = r.query(query, t, cam)
        mask = a["mask"]
        print(f"t = {t:.2f} s: level {a['level']} score {a['scores'][a['level']]:.3f}, "
              f"mask {mask.mean() * 100:.1f} % of the view")
        assert mask.shape == (240, 320) and mask.any()
    print("ok")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
