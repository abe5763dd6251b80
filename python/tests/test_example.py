"""The example script runs end to end on the real labelled scene."""

import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "encode_and_query.py"


def test_example_encode_and_query(labelled, work):
    out = work / "example.dlgs"
    p = subprocess.run([sys.executable, str(EXAMPLE), str(labelled), str(out)],
                       capture_output=True, text=True)
    print(p.stdout)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().endswith("ok")
    assert "GOP 2/2 encoded" in p.stdout
