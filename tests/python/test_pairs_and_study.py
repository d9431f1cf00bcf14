# tests/python/test_pairs_and_study.py — marbles.pairs against a NumPy brute
# force on random and adversarial sets; marbles.study as a table.
import numpy as np
import pytest

import marbles
from conftest import SCENES


def brute(xyzr, margin=0.0):
    x = xyzr.astype(np.float64)
    d = np.linalg.norm(x[:, None, :3] - x[None, :, :3], axis=2)
    reach = x[:, None, 3] + x[None, :, 3] + margin
    i, j = np.nonzero(np.triu(d <= reach, 1))
    return {(a, b) for a, b in zip(i.tolist(), j.tolist())}


def sets():
    rng = np.random.default_rng(7)
    gas = np.column_stack([rng.uniform(0, 1, (800, 3)), rng.uniform(0.005, 0.03, 800)])
    poly = np.column_stack([rng.uniform(0, 1, (400, 3)), rng.lognormal(-4, 1, 400).clip(0, 0.3)])
    same = np.tile([0.5, 0.5, 0.5, 0.1], (20, 1))  # every sphere at one point
    line = np.column_stack([np.arange(50) * 0.2, np.zeros(50), np.zeros(50), np.full(50, 0.1)])  # touching chain
    return {"gas": gas, "poly": poly, "same": same, "line": line}


@pytest.mark.parametrize("name", ["gas", "poly", "same", "line"])
@pytest.mark.parametrize("algorithm", ["home", "subdivision", "brute"])
def test_pairs_equal_brute_force(name, algorithm):
    xyzr = sets()[name].astype(np.float32)
    found = marbles.pairs(xyzr, backend="cpu", algorithm=algorithm)
    assert found.dtype == np.uint32 and found.shape[1] == 2
    assert (found[:, 0] < found[:, 1]).all()
    assert np.array_equal(found, np.array(sorted(map(tuple, found.tolist())), dtype=np.uint32).reshape(-1, 2))
    truth = brute(xyzr)
    got = {tuple(p) for p in found.tolist()}
    # float32 spheres exactly touching (the chain) may fall either side: all others must match
    if name == "line":
        assert got <= truth and len(truth - got) <= len(truth)
        assert len(got) >= 1
    else:
        assert got == truth


def test_spheres_too_far_apart_for_the_subdivision_name_the_algorithm():
    spread = np.array([[1e18, 0, 0, 1e-3], [-1e18, 0, 0, 1e-3], [0, 0, 0, 1e-3], [0, 0, 0.001, 1e-3]])
    with pytest.raises(marbles.SceneError, match=r"^algorithm: subdivision: the spheres span more than "
                                                 r"2\^62 cells.*; algorithm='home' or 'brute' take them$") as e:
        marbles.pairs(spread, backend="cpu", algorithm="subdivision")
    assert e.value.key == "algorithm"
    for algorithm in ("home", "brute"):
        assert marbles.pairs(spread, backend="cpu", algorithm=algorithm).tolist() == [[2, 3]]


def test_pairs_double_and_margin():
    xyzr = sets()["gas"]
    found = marbles.pairs(xyzr, backend="cpu", margin=0.01)
    assert {tuple(p) for p in found.tolist()} == brute(xyzr, 0.01)
    assert len(marbles.pairs(np.zeros((0, 4)))) == 0
    # Two spheres on one spot: found in double; too small for float's squares, refused there (not found apart).
    tiny = np.array([[0, 0, 0, 1e-25], [0, 0, 0, 1e-25]])
    assert marbles.pairs(tiny, backend="cpu").tolist() == [[0, 1]]
    with pytest.raises(marbles.SceneError, match="too small for float precision"):
        marbles.pairs(tiny.astype(np.float32), backend="cpu")


def test_study_returns_the_table(tmp_path):
    rows = marbles.study(SCENES / "validation" / "bouncing_ball.yaml", vary={"time.dt": [2e-3, 1e-3]},
                         set={"time.duration": 1.5}, backend="cpu", repeats=1, out=tmp_path)
    assert [r["time.dt"] for r in rows] == ["0.002", "0.001"]
    for r in rows:
        assert r["reference"] == "rebound_heights" and np.isfinite(r["error"]) and r["ms_per_step"] > 0
        assert r["steps"] == round(1.5 / float(r["time.dt"]))
    assert any(r["pareto"] for r in rows)
    assert (tmp_path / "study.csv").exists() and (tmp_path / "study.md").exists()
    with pytest.raises(marbles.SceneError):
        marbles.study(SCENES / "validation" / "bouncing_ball.yaml", vary={})


def test_a_study_replaces_a_users_files_only_when_told(tmp_path):
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    (tmp_path / "study.md").write_text("my notes")
    with pytest.raises(marbles.SceneError, match="study.md is there, and no earlier study") as refused:
        marbles.study(scene, vary={"time.dt": [2e-3]}, out=tmp_path)
    assert "give overwrite=True" in str(refused.value) and "--overwrite" not in str(refused.value)
    assert (tmp_path / "study.md").read_text() == "my notes"
    with pytest.raises(TypeError, match="study: overwrite is True or False"):
        marbles.study(scene, vary={"time.dt": [2e-3]}, out=tmp_path, overwrite="False")
    assert len(marbles.study(scene, vary={"time.dt": [2e-3]}, out=tmp_path, overwrite=True)) == 1
    assert (tmp_path / "study.md").read_text() != "my notes"
    assert len(marbles.study(scene, vary={"time.dt": [2e-3]}, out=tmp_path)) == 1  # its own files now


def test_a_studys_messages_name_the_functions_arguments(tmp_path):
    # The function's arguments, not the command line's options, which a
    # caller from Python did not give (and could not: it takes no --limit).
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    cases = [
        (dict(vary={"time.dt": [1e-3], "solver.iterations": list(range(1, 101))}, repeats=101),
         r"^vary: 10100 runs \(the settings' combinations x repeats 101\), more than the limit 10000 "
         r"\(a study from Python keeps to it"),
        (dict(vary={"time.dt": ["2e-3", "0.002"]}), r"^vary time.dt=2e-3,0.002: .*given twice.*\(repeats repeats"),
        (dict(vary={"solver.speculative": [True, "yes"]}), r"^vary: the settings .* make the same scene.*\(repeats "),
        (dict(vary={"backend": ["gpu"]}), r"^vary backend: expected one of auto, cpu, cuda"),
        (dict(vary={"precision": ["half"]}), r"^vary precision: expected one of float, double"),
    ]
    for kwargs, message in cases:
        with pytest.raises(marbles.SceneError, match=message) as refused:
            marbles.study(scene, out=tmp_path, **kwargs)
        assert "--" not in str(refused.value), str(refused.value)
    assert not any(tmp_path.iterdir())  # refused before anything ran


def test_study_twice_in_one_process(tmp_path):
    # The program's path comes from the submodule marbles._program; importing
    # it once must not shadow what the second study calls.
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    for k in range(2):
        rows = marbles.study(scene, vary={"time.dt": [2e-3]}, out=tmp_path / str(k))
        assert len(rows) == 1
