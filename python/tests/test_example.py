"""The example script runs end to end on the real labelled scene."""

import subprocess
import sys
from pathlib import Path

from conftest import run_cli

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "encode_and_query.py"


def test_example_encode_and_query(data, work):
    labelled = work / "labelled"
    ply = data / "ply" / "supersplat_fruit_drops_minimal_4721_sh3.ply"
    run_cli("labels", ply, "--annotations",
            data / "ply" / "supersplat_fruit_drops_minimal.annotations.json", "-o", labelled)
    out = work / "example.dlgs"
    p = subprocess.run([sys.executable, str(EXAMPLE), str(labelled), str(out)],
                       capture_output=True, text=True)
    print(p.stdout)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().endswith("ok")
    assert "GOP 2/2 encoded" in p.stdout
