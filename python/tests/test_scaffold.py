"""Scaffold-GS files (variant 1, the reference HAC run of tests/fixtures/scaffold_run encoded by
the CLI): frames need a camera, and equal the CLI's decode and render bit for bit."""

import json

import numpy as np
import pytest

import dlgs
from conftest import REPO, run_cli
from pngread import quantise, read_png8, read_png_rgb8
from test_roundtrip import assert_same

FIXTURE = REPO / "tests" / "fixtures" / "scaffold_run"
CAMERAS = FIXTURE / "reference_decode" / "cameras.json"
# GOP 0 between frames, and GOP 1.
TIMES = (0.425, 2.5)
SH_C0 = np.float32(0.2820948)


@pytest.fixture(scope="session")
def scaffold(cli, work):
    out = work / "scaffold.dlgs"
    run_cli("encode", FIXTURE, "-o", out)
    return out


def test_info_and_camera_required(scaffold):
    r = dlgs.open(scaffold)
    assert r.info["variant"] == "scaffold" and r.info["gop_count"] == 2
    with pytest.raises(ValueError, match="camera"):
        r.frame(0.5)
    with pytest.raises(dlgs.RequestError, match="per camera"):
        r.frame(0.5, camera=0, split=True)
    with pytest.raises(dlgs.RequestError):
        r.gop(0)
    with pytest.raises(dlgs.RequestError):
        list(iter(r))  # iteration has no camera


def test_frames_equal_cli_decode(scaffold, work):
    r = dlgs.open(scaffold)
    for t in TIMES:
        ply = work / f"scaffold_{t}.ply"
        run_cli("decode", scaffold, "--t", t, "-o", ply)
        # `dlgs decode`: orbit camera 0 of `dlgs render`, every anchor, with language
        f = r.frame(t, camera=0, language=True)
        assert f["sh"].shape[1:] == (1, 3) and f["lang_features"].shape[1] == 9
        assert len(f["positions"]) > 1000
        assert_same(f, dlgs.read_scene(ply))


def test_neural_arrays_are_the_mlp_outputs(scaffold):
    r = dlgs.open(scaffold)
    cam = json.loads(CAMERAS.read_text())[1]
    g = r.frame(2.5, camera=cam, language=True)
    n = r.frame(2.5, camera=cam, language=True, neural=True)
    assert np.array_equal(n["positions"], g["positions"])
    assert np.array_equal(n["rotations"], g["rotations"])
    # colours are RGB; the 3DGS form holds them as SH DC, (rgb - 0.5) / C0 in float32
    assert np.array_equal((n["colors"] - np.float32(0.5)) / SH_C0, g["sh"][:, 0, :])
    assert np.array_equal(n["lang_features"], g["lang_features"])
    assert ((n["opacities"] > 0) & (n["opacities"] < 1)).all()
    assert n["lang_opacities"].min() >= -1 and n["lang_opacities"].max() <= 1
    assert n["anchor"].dtype == np.uint32 and n["offset"].max() < 10
    assert (np.diff(n["anchor"].astype(np.int64)) >= 0).all()  # anchor by anchor
    assert "lang_features" not in r.frame(2.5, camera=cam, neural=True)


def test_culled_frame_keeps_whole_anchors(scaffold):
    r = dlgs.open(scaffold)
    cam = json.loads(CAMERAS.read_text())[1]
    full = r.frame(2.5, camera=cam, neural=True)
    culled = r.frame(2.5, camera=cam, neural=True, cull=True)
    assert 0 < len(culled["anchor"]) <= len(full["anchor"])
    kept = np.isin(full["anchor"], culled["anchor"])
    assert kept.sum() == len(culled["anchor"])  # every child of a kept anchor, in order
    for k in ("positions", "colors", "opacities"):
        assert np.array_equal(full[k][kept], culled[k])


def test_render_equals_cli_render(scaffold, work):
    r = dlgs.open(scaffold)
    cams = json.loads(CAMERAS.read_text())
    png = work / "scaffold_view1.png"
    run_cli("render", scaffold, "--cameras", CAMERAS, "--view", 1, "--t", 2.5, "--features",
            "-o", png)
    rgb, feats = r.render(2.5, cams[1], features=True)
    assert rgb.shape == (600, 800, 3) and feats.shape == (600, 800, 9)
    cli_feats = np.fromfile(png.with_suffix(".features.f32"), "<f4").reshape(600, 800, 9)
    assert np.array_equal(feats.view(np.uint32), cli_feats.view(np.uint32))
    assert np.array_equal(quantise(rgb), read_png_rgb8(png))
    # culling decodes fewer anchors for the same image
    assert np.array_equal(r.render(2.5, cams[1], cull=False).view(np.uint32),
                          rgb.view(np.uint32))
    assert rgb.std() > 0.01


def test_query_equals_cli(scaffold, labelled, work):
    """The neural Gaussians' language answers a query as `dlgs query` does (the HAC ingest
    stores no language decoder: it is given, with the negatives)."""
    r = dlgs.open(scaffold)
    cams = r.cameras(count=4, width=320, height=240)
    camfile = work / "scaffold_query_cams.json"
    camfile.write_text(json.dumps(cams))
    dec, neg = labelled / "lang_decoder.safetensors", labelled / "negatives.npy"
    with pytest.raises(dlgs.RequestError, match="lang_decoder"):
        r.query(np.load(labelled / "category_1.npy").reshape(-1), 0.5, cams[0])
    for view in (0, 2):
        prefix = work / f"scaffold_q_{view}"
        report = json.loads(run_cli(
            "query", scaffold, "--t", 0.5, "--text-embedding", labelled / "category_1.npy",
            "--lang-decoder", dec, "--negatives", neg, "--cameras", camfile, "--view", view,
            "-o", prefix, "--json"))[0]
        a = r.query(np.load(labelled / "category_1.npy").reshape(-1), 0.5, cams[view],
                    lang_decoder=dec, negatives=np.load(neg).astype(np.float32))
        assert a["level"] + 1 == report["level"]
        assert np.array_equal(np.float32(a["scores"]), np.float32(report["scores"]))
        assert int(a["mask"].sum()) == report["selected_pixels"]
        assert np.array_equal(read_png8(str(prefix) + ".mask.png", 1)[..., 0] == 255, a["mask"])
        assert np.ptp(a["relevance"]) > 0  # the language image is not constant
