# tests/python/conftest.py — what the tests of the Python module share.
#
# ctest runs them (python/CMakeLists.txt) with PYTHONPATH at build/python,
# MARBLES_PROGRAM at the program and MARBLES_SOURCE at the checkout. Tests
# marked `gpu` need a CUDA device and say "skipped: no CUDA device" without.
import copy
import os
import pathlib

import pytest

import marbles

SOURCE = pathlib.Path(os.environ.get("MARBLES_SOURCE", pathlib.Path(__file__).resolve().parents[2]))
SCENES = SOURCE / "scenes"
PROGRAM = os.environ.get("MARBLES_PROGRAM", str(SOURCE / "build" / "bin" / "marbles"))
HAS_CUDA = marbles.cuda_device()[0]

# A small frictional pile in a box: 5 x 5 x 4 glass spheres on a loose lattice.
PILE = {
    "name": "pile",
    "time": {"duration": 0.5, "dt": 1e-3},
    "effects": ["gravity", "collisions", "walls", "restitution", "friction"],
    "materials": {"glass": {"density": 2500, "restitution": 0.3, "friction": 0.5}},
    "walls": [{"box": {"min": [0, 0, 0], "max": [0.1, 0.1, 0.3]}}],
    "particles": [{"lattice": {"min": [0.01, 0.01, 0.01], "max": [0.09, 0.09, 0.09], "spacing": 0.02,
                               "radius": 0.0095, "jitter": 0.0005, "seed": 3}}],
}


def pytest_configure(config):
    config.addinivalue_line("markers", "gpu: needs a CUDA device")


def pytest_collection_modifyitems(config, items):
    if HAS_CUDA:
        return
    skip = pytest.mark.skip(reason="skipped: no CUDA device")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def pile():
    return copy.deepcopy(PILE)
