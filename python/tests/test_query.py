"""Queries equal `dlgs query`'s: scores, chosen level, mask pixels."""

import json

import numpy as np

import dlgs
from conftest import run_cli
from pngread import read_png8


def test_query_equals_cli(labelled, work):
    path = work / "labelled.dlgs"
    run_cli("encode", labelled / "scene.ply", "-o", path, "--lang-decoder",
            labelled / "lang_decoder.safetensors", "--negatives", labelled / "negatives.npy")
    r = dlgs.open(path)
    cams = r.cameras(count=4, width=320, height=240)
    camfile = work / "query_cams.json"
    camfile.write_text(json.dumps(cams))
    for cat in (1, 4):
        emb = np.load(labelled / f"category_{cat}.npy").reshape(-1)
        for view in (0, 2):
            prefix = work / f"q_{cat}_{view}"
            report = json.loads(run_cli(
                "query", path, "--text-embedding", labelled / f"category_{cat}.npy",
                "--cameras", camfile, "--view", view, "-o", prefix, "--json"))[0]
            a = r.query(emb, 0.0, cams[view])
            assert a["level"] + 1 == report["level"]
            assert np.array_equal(np.float32(a["scores"]), np.float32(report["scores"]))
            assert int(a["mask"].sum()) == report["selected_pixels"]
            png = read_png8(str(prefix) + ".mask.png", 1)[..., 0]
            assert np.array_equal(png == 255, a["mask"])
            assert a["relevance"].shape == (3, 240, 320) and a["mask"].dtype == np.bool_
    both = r.query(np.stack([np.load(labelled / f"category_{c}.npy").reshape(-1)
                             for c in (1, 4)]), 0.0, cams[0])
    assert isinstance(both, list) and len(both) == 2
