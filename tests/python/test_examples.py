# tests/python/test_examples.py — the examples in examples/python run (in
# their quick forms) and reach their own checks.
import re
import subprocess
import sys

import pytest

from conftest import SOURCE

EXAMPLES = SOURCE / "examples" / "python"


def run(script, *args):
    done = subprocess.run([sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_restitution_sweep(tmp_path):
    out = run("restitution_sweep.py", "--quick", "--out", str(tmp_path))
    worst = float(re.search(r"largest error ([0-9.]+) %", out).group(1))
    assert worst < 2.0  # rebounds against h0 e^(2k)
    try:
        import matplotlib  # noqa: F401
        assert (tmp_path / "restitution_sweep.png").stat().st_size > 0
    except ImportError:
        assert "no plot" in out


def test_hopper_discharge():
    out = run("hopper_discharge.py", "--quick", "--backend", "cpu")
    assert "the plug is out" in out and "discharge:" in out


def test_pairs_vs_kdtree():
    pytest.importorskip("scipy")
    out = run("pairs_vs_kdtree.py", "--n", "20000", "--backend", "cpu", "--repeats", "1")
    assert "the same pairs: True" in out
