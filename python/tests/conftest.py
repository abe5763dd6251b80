"""Shared fixtures: the real data, the `dlgs` CLI (the reference the bindings are checked
against) and small dynamic models made by `dlgs synth` from a real scene."""

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def data_dir() -> Path:
    return Path(os.environ.get("DLGS_DATA", REPO.parent / "shared" / "data"))


def cli_path() -> Path:
    if "DLGS_CLI" in os.environ:
        return Path(os.environ["DLGS_CLI"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "dlgs"


def run_cli(*args) -> str:
    """Run the CLI; fail the test with its output if it fails."""
    p = subprocess.run([str(cli_path()), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, f"dlgs {' '.join(map(str, args))}:\n{p.stdout}\n{p.stderr}"
    return p.stdout


@pytest.fixture(scope="session")
def data() -> Path:
    d = data_dir()
    if not (d / "MANIFEST.md").exists():
        pytest.fail(f"real data not found at {d} (set DLGS_DATA)")
    return d


@pytest.fixture(scope="session")
def cli() -> Path:
    p = cli_path()
    if not p.exists():
        pytest.fail(f"the dlgs CLI is not built at {p} (cargo build --release -p dlgs-cli)")
    return p


@pytest.fixture(scope="session")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("dlgs")


@pytest.fixture(scope="session")
def dyn_exact(data, cli, work) -> Path:
    """A SYNTHETIC motion model on the real plant scene: 2 GOPs of 20 frames, 3,000 dynamic
    Gaussians with language, time features stored exactly."""
    out = work / "dyn_exact.dlgs"
    run_cli("synth", data / "splat" / "marcelpadilla_plant.splat", "-o", out,
            "--gops", 2, "--gop-length", 20, "--key-interval", 10, "--max-dynamic", 3000,
            "--language", "--exact-features")
    return out


@pytest.fixture(scope="session")
def labelled(data, cli, work) -> Path:
    """The real fruit scene with SYNTHETIC language from its REAL per-Gaussian labels
    (`dlgs labels`): scene.ply, lang_decoder.safetensors, negatives.npy, category_N.npy."""
    out = work / "labelled"
    ply = data / "ply" / "supersplat_fruit_drops_minimal_4721_sh3.ply"
    run_cli("labels", ply, "--annotations",
            data / "ply" / "supersplat_fruit_drops_minimal.annotations.json", "-o", out)
    return out


@pytest.fixture(scope="session")
def dyn_hevc(dyn_exact, cli, work) -> Path:
    """`dyn_exact` re-encoded by the CLI with HEVC time features (crf 6)."""
    out = work / "dyn_hevc.dlgs"
    run_cli("encode", dyn_exact, "-o", out, "--crf", 6)
    return out
