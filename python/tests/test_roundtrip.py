"""numpy -> Writer -> .dlgs -> frame(t): exact for lossless settings; the bytes are the CLI's."""

import numpy as np
import pytest

import dlgs
from conftest import run_cli

KEYS = ("positions", "log_scales", "rotations", "opacities", "sh", "lang_features", "lang_opacities")


def assert_same(a: dict, b: dict):
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == np.float32 and a[k].shape == b[k].shape, k
        assert np.array_equal(a[k].view(np.uint32), b[k].view(np.uint32)), k


def random_scene(n, sh_coeffs=4, lang=9, seed=0):
    rng = np.random.default_rng(seed)
    s = {
        "positions": rng.normal(size=(n, 3)).astype(np.float32),
        "log_scales": rng.normal(-4, 0.5, size=(n, 3)).astype(np.float32),
        "rotations": rng.normal(size=(n, 4)).astype(np.float32),
        "opacities": rng.normal(size=n).astype(np.float32),
        "sh": rng.normal(0, 0.3, size=(n, sh_coeffs, 3)).astype(np.float32),
    }
    if lang:
        s["lang_features"] = rng.normal(size=(n, lang)).astype(np.float32)
        s["lang_opacities"] = rng.normal(size=n).astype(np.float32)
    return s


def test_still_lossless_round_trip(work):
    scene = random_scene(5000)
    path = work / "still.dlgs"
    with dlgs.Writer(path, quality="lossless") as w:
        w.write_gop(scene)
    r = dlgs.open(path)
    assert r.info["n_static"] == 5000 and r.info["frame_count"] == 1
    assert r.info["sh_degree"] == 1 and r.info["lang_width"] == 9
    assert_same(r.frame(0.0, language=True), scene)
    # float64 and non-contiguous inputs are converted, not refused
    s64 = {k: np.asfortranarray(v.astype(np.float64)) for k, v in scene.items()}
    with dlgs.Writer(work / "still64.dlgs") as w:
        w.write_gop(s64)
    assert (work / "still64.dlgs").read_bytes() == path.read_bytes()


def test_dynamic_round_trip_exact(dyn_exact, work):
    """GOPs read as arrays, written back (lossless, exact features): the same arrays, the
    same frames bit for bit, and the same bytes as `dlgs encode --exact-features`."""
    src = dlgs.open(dyn_exact)
    info = src.info
    gops = [src.gop(g) for g in range(info["gop_count"])]
    assert gops[0]["time_features"].shape == (info["n_dynamic"], 3, 16)
    out = work / "rewritten_exact.dlgs"
    progress = []
    with dlgs.Writer(out, fps=info["fps"], gop_length=info["gop_length"], exact_features=True,
                     progress=lambda d, t: progress.append((d, t))) as w:
        for g in gops:
            w.write_gop(g["static"], g["dynamic"], g["time_features"], g["decoders"],
                        g["scale_offsets"])
    assert progress == [(1, 2), (2, 2)]
    back = dlgs.open(out)
    assert back.info == info
    for g, orig in enumerate(gops):
        again = back.gop(g)
        assert_same(again["static"], orig["static"])
        assert_same(again["dynamic"], orig["dynamic"])
        assert np.array_equal(again["time_features"], orig["time_features"])
        for role, layers in orig["decoders"].items():
            for a, b in zip(again["decoders"][role], layers):
                assert np.array_equal(a, b)
    for t in (0.0, 0.1234, 0.5, 0.99, 1.3):
        for cam in (None, 0, 3):
            assert_same(back.frame(t, camera=cam, language=True),
                        src.frame(t, camera=cam, language=True))
    cli_out = work / "cli_exact.dlgs"
    run_cli("encode", dyn_exact, "-o", cli_out, "--exact-features", "--no-meta")
    assert out.read_bytes() == cli_out.read_bytes()


def test_quantised_features_same_bytes_as_cli(dyn_exact, work):
    """Time features quantised to 8 bits (TFEA codec 4, the web player's codec): the CLI's
    bytes; frames within the quantisation of the exact ones; a depth outside 6-12 refused."""
    src = dlgs.open(dyn_exact)
    info = src.info
    out = work / "rewritten_q8.dlgs"
    with dlgs.Writer(out, fps=info["fps"], gop_length=info["gop_length"],
                     quantised_features=8) as w:
        for g in range(info["gop_count"]):
            d = src.gop(g)
            w.write_gop(d["static"], d["dynamic"], d["time_features"], d["decoders"],
                        d["scale_offsets"])
    cli_out = work / "cli_q8.dlgs"
    run_cli("encode", dyn_exact, "-o", cli_out, "--quantised-features", 8, "--no-meta")
    assert out.read_bytes() == cli_out.read_bytes()
    back = dlgs.open(out)
    f0, f1 = src.gop(0)["time_features"], back.gop(0)["time_features"]
    step = (f0.max(axis=(0, 1)) - f0.min(axis=(0, 1))) / 255
    assert np.all(np.abs(f1 - f0) <= step * 0.5 + 1e-5)
    assert not np.array_equal(f1, f0)
    with pytest.raises(Exception, match="6 to 12"):
        dlgs.Writer(work / "bad.dlgs", quantised_features=5)


@pytest.mark.parametrize("fast_start", ["first", "off"])
def test_dynamic_hevc_same_bytes_as_cli(dyn_exact, work, fast_start):
    """crf 6 HEVC time features, streamed (gop_count given): the CLI's bytes, with the
    default fast start and without."""
    src = dlgs.open(dyn_exact)
    info = src.info
    out = work / f"rewritten_hevc_{fast_start}.dlgs"
    w = dlgs.Writer(out, fps=info["fps"], gop_length=info["gop_length"], crf=6,
                    gop_count=info["gop_count"], fast_start=fast_start)
    for g in range(info["gop_count"]):
        d = src.gop(g)
        w.write_gop(d["static"], d["dynamic"], d["time_features"], d["decoders"], d["scale_offsets"])
        assert not out.exists()
    size = w.close()
    cli_out = work / f"cli_hevc_{fast_start}.dlgs"
    run_cli("encode", dyn_exact, "-o", cli_out, "--crf", 6, "--no-meta",
            "--fast-start", fast_start)
    assert size == cli_out.stat().st_size
    assert out.read_bytes() == cli_out.read_bytes()


def test_fast_start_option_is_checked(work):
    with pytest.raises(dlgs.RequestError, match="fast_start"):
        dlgs.Writer(work / "x.dlgs", fast_start="sometimes")


def test_writer_refuses_bad_input(work):
    scene = random_scene(10, lang=0)
    w = dlgs.Writer(work / "bad.dlgs")
    bad = dict(scene, positions=scene["positions"][:, :2])
    with pytest.raises(dlgs.InputError) as e:
        w.write_gop(bad)
    assert e.value.kind == "Input" and "positions" in e.value.message
    with pytest.raises(dlgs.InputError):
        w.write_gop(scene, dynamic=scene)  # dynamic Gaussians without time features
    with pytest.raises(dlgs.RequestError):
        dlgs.Writer(work / "bad2.dlgs", quality="ultra")
    nan = dict(scene, opacities=np.full(10, np.nan, np.float32))
    w.write_gop(nan)
    with pytest.raises(dlgs.DlgsError):
        w.close()
    assert not (work / "bad.dlgs").exists()


def test_explicit_residuals_round_trip(work):
    """residual_mode sequential: GOPs after the first are coded as explicit residuals (RDLT)
    against the decoded previous GOP; lossless settings keep every state exactly."""
    rng = np.random.default_rng(3)
    states = [random_scene(3000, lang=9, seed=1)]
    for _ in range(2):
        nxt = {k: v.copy() for k, v in states[-1].items()}
        moved = rng.random(3000) < 0.2
        nxt["positions"][moved] += rng.normal(0, 0.01, (int(moved.sum()), 3)).astype(np.float32)
        nxt["opacities"][moved] += np.float32(0.5)
        states.append(nxt)
    path = work / "residuals.dlgs"
    with dlgs.Writer(path, fps=10, gop_length=5, residual_mode="sequential") as w:
        for s in states:
            w.write_gop(s)
    r = dlgs.open(path)
    assert r.info["residual_mode"] == "Sequential" and r.info["gop_count"] == 3
    for g, s in enumerate(states):
        assert_same(r.frame(g * 0.5 + 0.1, language=True), s)
    intra = work / "intra.dlgs"
    with dlgs.Writer(intra, fps=10, gop_length=5) as w:
        for s in states:
            w.write_gop(s)
    assert path.stat().st_size < intra.stat().st_size


def test_residual_fields_pass_through_as_the_cli(data, work):
    """A sequential scene whose GOPs after the first are binary voxel residual fields (RNTC):
    read as arrays, written back with them, the same bytes as `dlgs encode` (which keeps the
    fields when lossless) and the same frames."""
    src_path = work / "ntc_exact.dlgs"
    run_cli("synth", data / "splat" / "marcelpadilla_plant.splat", "-o", src_path,
            "--gops", 3, "--gop-length", 10, "--key-interval", 5, "--max-dynamic", 2000,
            "--residual-mode", "sequential", "--exact-features")
    src = dlgs.open(src_path)
    info = src.info
    assert info["residual_mode"] == "Sequential"
    gops = [src.gop(g) for g in range(info["gop_count"])]
    assert "residual_field" not in gops[0]
    assert all("residual_field" in g for g in gops[1:])
    f = gops[1]["residual_field"]
    assert f["gate"].dtype == np.uint8 and len(f["planes"]) == 3 * len(f["resolutions"])
    out = work / "ntc_rewritten.dlgs"
    with dlgs.Writer(out, fps=info["fps"], gop_length=info["gop_length"], exact_features=True,
                     residual_mode="sequential") as w:
        for i, g in enumerate(gops):
            if i == 0:
                w.write_gop(g["static"], g["dynamic"], g["time_features"], g["decoders"],
                            g["scale_offsets"])
            else:
                w.write_gop(None, None, g["time_features"], g["decoders"], g["scale_offsets"],
                            residual_field=g["residual_field"])
    cli_out = work / "ntc_cli.dlgs"
    run_cli("encode", src_path, "-o", cli_out, "--exact-features", "--no-meta")
    assert out.read_bytes() == cli_out.read_bytes()
    back = dlgs.open(out)
    for t in (0.05, 0.4, 0.77):
        assert_same(back.frame(t, language=True), src.frame(t, language=True))


def _assert_nearest(x, got, codebook):
    """Each value of `got` is the codebook entry nearest the value of `x` (the codebook is
    sorted and holds float32 values)."""
    book = np.asarray(codebook, np.float32).astype(np.float64)
    assert np.all(np.isin(got.astype(np.float64), book))
    x = x.astype(np.float64).ravel()
    i = np.clip(np.searchsorted(book, x), 1, len(book) - 1)
    best = np.minimum(np.abs(x - book[i - 1]), np.abs(x - book[i]))
    assert np.array_equal(np.abs(x - got.astype(np.float64).ravel()), best)


def test_sog_written_and_read_back(work):
    """SOG out (bundled and unbundled), our reader back: every attribute within SOG's
    quantisation (16-bit log-domain positions, 8-bit rotations and opacity, the nearest entry of
    256-entry codebooks; below 65,536 Gaussians every SH-rest vector is its own palette entry)."""
    import json
    scene = random_scene(3000, sh_coeffs=16)
    n_bytes = dlgs.write_scene(work / "scene.sog", scene)
    assert n_bytes == (work / "scene.sog").stat().st_size
    unbundled = work / "sog_dir"
    unbundled.mkdir()
    dlgs.write_scene(unbundled / "meta.json", scene)
    dlgs.write_scene(work / "scene.bin", scene, format="sog")
    assert (work / "scene.bin").read_bytes() == (work / "scene.sog").read_bytes()
    back = dlgs.read_scene(work / "scene.sog")
    assert_same(back, dlgs.read_scene(unbundled / "meta.json"))
    assert set(back) == {"positions", "log_scales", "rotations", "opacities", "sh"}
    meta = json.loads((unbundled / "meta.json").read_text())
    assert meta["version"] == 2 and meta["count"] == 3000 and meta["shN"]["count"] == 3000
    p, q = scene["positions"], back["positions"]
    assert np.all(np.abs(p - q) <= 2e-4 * (1 + np.abs(p)))
    _assert_nearest(scene["log_scales"], back["log_scales"], meta["scales"]["codebook"])
    _assert_nearest(scene["sh"][:, 0], back["sh"][:, 0], meta["sh0"]["codebook"])
    _assert_nearest(scene["sh"][:, 1:], back["sh"][:, 1:], meta["shN"]["codebook"])
    for k in ("scales", "sh0", "shN"):  # 256-entry codebooks, fitted (not a fixed grid)
        assert len(meta[k]["codebook"]) == 256
    rot = scene["rotations"] / np.linalg.norm(scene["rotations"], axis=1, keepdims=True)
    assert np.all(np.abs(np.sum(rot * back["rotations"], axis=1)) > 0.995)
    sig = lambda x: 1 / (1 + np.exp(-x.astype(np.float64)))  # noqa: E731
    assert np.all(np.abs(sig(scene["opacities"]) - sig(back["opacities"])) <= 0.5 / 255 + 1e-6)


def test_read_ahead_changes_no_bit(dyn_exact):
    """Frames asked for in time order (the next GOP decoded on a background thread) equal the
    frames of a reader that decodes each GOP in turn."""
    ahead, plain = dlgs.open(dyn_exact), dlgs.open(dyn_exact, read_ahead=False)
    info = ahead.info
    times = [f / info["fps"] for f in range(0, info["frame_count"], 3)]
    assert len({int(t * info["fps"]) // info["gop_length"] for t in times}) >= 2
    for t in times:
        assert_same(ahead.frame(t, language=True), plain.frame(t, language=True))
