# tests/python/test_simulation.py — stepping, the state as arrays, contacts,
# frames and checkpoints from Python, each against an oracle: the program
# itself (marbles run), NumPy arithmetic on the arrays, the laws of statics.
import gc
import json
import math
import pathlib
import subprocess
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import marbles
from conftest import PROGRAM, SCENES


def test_step_and_run_advance_time(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    assert (sim.steps, sim.time, len(sim)) == (0, 0.0, 4 * 4 * 4)
    sim.step()
    sim.step(4)
    assert sim.steps == 5 and sim.time == pytest.approx(5 * sim.dt)
    seen = []
    sim.run(until=0.02, callback=lambda s: seen.append(s.steps), every=4)
    assert sim.steps == 20 and seen == [9, 13, 17, 20]
    sim.run(until=0.03, callback=lambda s: False, every=2)  # False stops the run
    assert sim.steps == 22
    assert "contact solver" in sim.pipeline and "friction" in sim.pipeline
    assert sim.backend == "cpu" and sim.precision == "float"
    with pytest.raises(ValueError):
        sim.step(-1)


def test_views_are_the_step_arrays(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    x = sim.positions
    assert x.shape == (len(sim), 3) and x.dtype == np.float32 and x.flags.writeable
    before = x.copy()
    sim.step(3)
    # the same memory, moved by the step (no copy was made)
    assert np.shares_memory(x, sim.positions)
    assert not np.array_equal(before, x)
    assert np.array_equal(x, sim.positions)
    for name in ("radii", "materials", "ids"):
        assert not getattr(sim, name).flags.writeable
    with pytest.raises(ValueError):
        sim.radii[0] = 1.0


def test_writes_through_views_change_the_next_step(pile):
    # Oracle: the same edit made by assignment (a copy) in a twin.
    edited = marbles.Simulation.from_dict(pile, backend="cpu")
    twin = marbles.Simulation.from_dict(pile, backend="cpu")
    for s in (edited, twin):
        s.step(5)
    kick = np.zeros((len(twin), 3), np.float32)
    kick[7] = [0.3, -0.2, 1.5]
    edited.velocities[7] += kick[7]          # in place, through the view
    twin.velocities = twin.velocities + kick  # assigned
    untouched = marbles.Simulation.from_dict(pile, backend="cpu")
    untouched.step(5)
    for s in (edited, twin, untouched):
        s.step(5)
    assert np.array_equal(edited.positions, twin.positions)
    assert np.array_equal(edited.velocities, twin.velocities)
    assert not np.array_equal(edited.positions, untouched.positions)


def test_reading_the_state_is_no_edit():
    # A box with 100 spheres dropped at one point: the watchdog refuses the
    # first step (spheres pushed through a wall, every retry). Reading the
    # state first, through any view or a copy, writes nothing: the step is
    # judged as it is without the read (it was taken for an edit, which the
    # watchdog does not judge, and the step passed with spheres outside).
    scene = {"time": {"duration": 0.5, "dt": 1e-3}, "effects": ["gravity", "collisions", "walls"],
             "materials": {"glass": {"density": 2500}},
             "walls": [{"box": {"min": [0, 0, 0], "max": [0.1, 0.1, 0.3]}}],
             "particles": [{"list": {"positions": [[0.05, 0.05, 0.05]] * 100, "radius": 0.01}}]}
    reads = [None, lambda s: s.radii, lambda s: s.materials, lambda s: s.positions,
             lambda s: s.velocities.copy(), lambda s: s.angular_velocities, lambda s: s.contacts()]
    for read in reads:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = marbles.Simulation.from_dict(scene, backend="cpu", threads=1)
        if read:
            read(sim)
        with pytest.raises(marbles.RuntimeFailure, match="went through a wall"):
            sim.step()
        assert sim.steps == 0
    # A value written back unchanged is no edit either; a changed one is (the
    # step then starts from it unjudged, as after an assignment).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = marbles.Simulation.from_dict(scene, backend="cpu", threads=1)
    x = sim.positions
    x[3] = x[3].copy()
    with pytest.raises(marbles.RuntimeFailure, match="went through a wall"):
        sim.step()


def test_non_finite_writes_are_refused(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    sim.step(2)
    x = sim.positions
    good = x[4, 1]
    x[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions\[4\] is not finite"):
        sim.step()
    assert sim.steps == 2  # nothing moved
    x[4, 1] = good
    sim.step()
    assert sim.steps == 3
    v = np.array(sim.velocities)
    v[2, 0] = np.inf
    with pytest.raises(ValueError, match=r"velocities\[2\] is not finite"):
        sim.velocities = v
    with pytest.raises(ValueError, match="shape"):
        sim.angular_velocities = np.zeros((3, 3))
    assert np.isfinite(sim.velocities).all()
    # Finite, but its square past the precision's range (its kinetic energy
    # would be inf): refused through a view as in an assignment.
    big = np.sqrt(np.finfo(sim.angular_velocities.dtype).max) * 2
    w = sim.angular_velocities
    w[3] = [big, 0, 0]
    with pytest.raises(ValueError, match=r"angular_velocities\[3\] is too large for float precision: its squared"):
        sim.step()
    assert sim.steps == 3
    w[3] = 0
    sim.step()
    assert np.isfinite(sim.kinetic_energy())


def test_kinetic_energy_from_the_arrays(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    sim.step(30)
    r = sim.radii.astype(np.float64)
    m = 2500 * 4 / 3 * np.pi * r**3
    inertia = 0.4 * m * r**2
    v = sim.velocities.astype(np.float64)
    w = sim.angular_velocities.astype(np.float64)
    expected = 0.5 * (m * (v**2).sum(1)).sum() + 0.5 * (inertia * (w**2).sum(1)).sum()
    assert expected > 0
    assert sim.kinetic_energy() == pytest.approx(expected, rel=1e-5)


def test_contacts_of_a_resting_pile_carry_its_weight(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    sim.run(until=1.0)  # at rest: the last spheres to slip stop by 0.8 s
    assert sim.kinetic_energy() < 1e-5
    c = sim.contacts()
    m_total = (2500 * 4 / 3 * np.pi * sim.radii.astype(np.float64) ** 3).sum()
    wall = c["wall"]
    # statics: the walls' forces (normal and friction) on the pile carry its whole weight
    force = c["normal_force"][:, None] * c["normal"] + c["tangential_force"]
    assert force[wall, 2].astype(np.float64).sum() == pytest.approx(m_total * 9.81, rel=0.02)
    # (sideways the walls balance to within the solver's residual: 10 sweeps, not converged)
    assert np.abs(force[wall, :2].astype(np.float64).sum(0)).max() < 0.05 * m_total * 9.81
    assert (c["normal_force"] >= 0).all()
    # every sphere-sphere contact is a pair of spheres within touch (the broad phase's brute oracle)
    xyzr = np.column_stack([sim.positions, sim.radii])
    near = {tuple(p) for p in marbles.pairs(xyzr, algorithm="brute", margin=1e-4)}
    spheres = c["pairs"][~c["wall"]]
    assert len(spheres) > len(sim)
    assert all(tuple(sorted(p)) in near for p in spheres)
    assert (c["pairs"][wall][:, 1] < 6).all()  # the box is six wall faces


def test_python_run_equals_marbles_run(tmp_path):
    # marbles run writes a checkpoint at its last step; the Python run of the
    # same scene and overrides reaches the same bits.
    scene = SCENES / "demo.yaml"
    overrides = ["time.duration=0.06", "output.checkpoint={every: 60, keep: 1}"]
    out = tmp_path / "run"
    args = [PROGRAM, "run", str(scene), "--out", str(out), "--summary-only", "--quiet", "--backend", "cpu"]
    for o in overrides:
        args += ["--set", o]
    subprocess.run(args, check=True, capture_output=True)
    sim = marbles.Simulation(scene, backend="cpu", set=overrides)
    sim.run()
    assert sim.steps == 60
    done = marbles.Simulation.restart(out / "checkpoints" / "step_000060.mck", scene=scene, backend="cpu",
                                      set=overrides)
    assert done.steps == 60
    for name in ("positions", "velocities", "angular_velocities"):
        assert np.array_equal(getattr(sim, name), getattr(done, name)), name
    summary = json.loads((out / "summary.json").read_text())
    assert sim.kinetic_energy() == summary["kinetic_energy_end"]
    for key in ("kinetic_energy_end_translational", "kinetic_energy_end_rotational", "max_speed_end"):
        assert sim.summary()[key] == summary[key], key
    assert sim.summary()["max_overlap"] == summary["max_overlap"]
    assert sim.summary()["scene_name"] == summary["scene_name"]


def test_restart_takes_a_marbles_run_checkpoint_in_double(tmp_path):
    # marbles run --precision double writes a double checkpoint of a float
    # scene; restart() resumes it in double with the run's overrides (the
    # precision is no override: the checkpoint's fingerprint holds). The
    # scene is built once, in double: its warning (a mass ratio of 50 at a
    # substep of 1 ms) is said once, at the caller's line.
    scene = SCENES / "demo.yaml"
    overrides = ["time.duration=0.03", "output.checkpoint={every: 30, keep: 1}", "materials.steel.density=15600"]
    out = tmp_path / "run"
    args = [PROGRAM, "run", str(scene), "--out", str(out), "--summary-only", "--quiet", "--backend", "cpu",
            "--precision", "double"]
    for o in overrides:
        args += ["--set", o]
    subprocess.run(args, check=True, capture_output=True)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        done = marbles.Simulation.restart(out / "checkpoints" / "step_000030.mck", scene=scene, backend="cpu",
                                          set=overrides)
    assert ["times heavier than the lightest" in str(w.message) for w in said] == [True], [str(w.message) for w in said]
    assert said[0].filename == __file__
    assert done.precision == "double" and done.steps == 30
    assert done.positions.dtype == np.float64
    sim = marbles.Simulation(scene, backend="cpu", set=overrides + ["solver.precision=double"])
    sim.run()
    assert np.array_equal(sim.positions, done.positions)


def test_checkpoint_and_restart_go_on_bit_for_bit(pile, tmp_path):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    sim.step(10)
    path = tmp_path / "c.mck"
    sim.checkpoint(path)
    # The checkpoint and the scene's record, each renamed from its temporary: nothing else is left.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.mck", "c.mck.scene.json"]
    sim.checkpoint(path)  # again over both
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.mck", "c.mck.scene.json"]
    sim.step(10)
    again = marbles.Simulation.restart(path, backend="cpu")  # the scene from path.scene.json
    assert again.steps == 10
    again.step(10)
    assert np.array_equal(sim.positions, again.positions)
    assert np.array_equal(sim.angular_velocities, again.angular_velocities)
    with pytest.raises(marbles.SceneError, match="another scene"):
        marbles.Simulation.restart(path, scene=SCENES / "demo.yaml")
    (tmp_path / "c.mck.scene.json").unlink()
    with pytest.raises(marbles.SceneError, match="scene="):
        marbles.Simulation.restart(path)


def test_restart_takes_the_same_scene_in_other_texts(pile, tmp_path):
    # The checkpoint holds the scene as read: overrides that read alike (in
    # another order, 5e-4 as 0.0005, True as true, quoted) resume it, from
    # the record or a scene given anew; another value is refused.
    sim = marbles.Simulation.from_dict(pile, backend="cpu", set=["time.dt=5e-4", "solver.speculative=true"])
    sim.step(10)
    path = tmp_path / "c.mck"
    sim.checkpoint(path)
    sim.step(10)
    for form in (["solver.speculative=True", "time.dt=0.0005"], {"time.dt": 0.0005, "solver.speculative": True},
                 ['time.dt="5e-4"', "solver={speculative: yes}"]):
        again = marbles.Simulation.restart(path, backend="cpu", set=form)
        assert again.steps == 10, form
        again.step(10)
        assert np.array_equal(sim.positions, again.positions), form
    same = marbles.Simulation.restart(path, scene=pile, backend="cpu",
                                      set={"time.dt": 5e-4, "solver.speculative": True})
    assert same.steps == 10
    with pytest.raises(marbles.SceneError, match="another scene"):
        marbles.Simulation.restart(path, backend="cpu", set={"time.dt": 4e-4, "solver.speculative": True})


def test_restart_takes_a_checkpoint_of_the_texts(pile, tmp_path, monkeypatch):
    # A checkpoint of the earlier fingerprint (a hash of the file's bytes and
    # the overrides' texts, FNV-1a) still resumes its scene file with the
    # same texts; others, even alike, are refused (the texts are all it has).
    scene = tmp_path / "s.yaml"
    scene.write_text(json.dumps(pile))  # JSON is YAML
    monkeypatch.chdir(tmp_path)
    sim = marbles.Simulation("s.yaml", backend="cpu", set=["time.dt=5e-4"])
    sim.step(5)
    ck = tmp_path / "c.mck"
    sim.checkpoint(ck)
    data = bytearray(ck.read_bytes())

    def fnv1a(data, h=14695981039346656037):
        for byte in data:
            h = ((h ^ byte) * 1099511628211) % 2**64
        return h

    texts = fnv1a(b"time.dt=5e-4\0", fnv1a(scene.read_bytes()))
    data[8 + 4 + 16 + 4 + 4:8 + 4 + 16 + 4 + 4 + 8] = texts.to_bytes(8, "little")  # after magic, format, version, sizes
    data[-8:] = fnv1a(data[:-8]).to_bytes(8, "little")
    ck.write_bytes(bytes(data))
    resumed = marbles.Simulation.restart(ck, scene="s.yaml", backend="cpu", set=["time.dt=5e-4"])
    assert resumed.steps == 5
    resumed.step(5)
    sim.step(5)
    assert np.array_equal(sim.positions, resumed.positions)
    with pytest.raises(marbles.SceneError, match="another scene"):
        marbles.Simulation.restart(ck, scene="s.yaml", backend="cpu", set=["time.dt=0.0005"])


def test_double_precision_scene(pile):
    pile["solver"] = {"precision": "double"}
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    assert sim.precision == "double" and sim.positions.dtype == np.float64
    single = marbles.Simulation.from_dict(pile, backend="cpu", set={"solver.precision": "float"})
    assert single.precision == "float"
    # A set of it in any form the loader takes: nested, quoted, in a map of the solver (from a dict and a file).
    del pile["solver"]
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    for form in ({"solver": {"precision": "double"}}, ['solver.precision="double"'],
                 ["solver={precision: double, iterations: 5}"]):
        assert marbles.Simulation.from_dict(pile, backend="cpu", set=form).precision == "double", form
        assert marbles.Simulation(scene, backend="cpu", set=form).precision == "double", form
    assert marbles.Simulation(scene, backend="cpu", set=["solver={iterations: 5}"]).precision == "float"
    sim.step(20)
    single.step(20)
    assert np.allclose(sim.positions, single.positions, atol=1e-5)


def test_write_frame(pile, tmp_path):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    first = sim.write_frame(tmp_path)
    sim.step(5)
    second = sim.write_frame(tmp_path)
    assert pathlib.Path(first).name == "frame_000000.vtp" and pathlib.Path(second).name == "frame_000001.vtp"
    datasets = ET.parse(tmp_path / "series.pvd").getroot().iter("DataSet")
    times = [float(d.get("timestep")) for d in datasets]
    assert times == [0.0, pytest.approx(5 * sim.dt)]
    head = pathlib.Path(second).read_bytes()[:4000].decode("latin-1")
    assert f'NumberOfPoints="{len(sim)}"' in head
    # Another simulation's frames in that folder are refused, not mixed in
    # (frame_000000 replaced, series.pvd naming one frame of two).
    other = marbles.Simulation.from_dict(pile, backend="cpu")
    before = (tmp_path / "series.pvd").read_bytes(), pathlib.Path(first).read_bytes()
    with pytest.raises(marbles.SceneError, match="another series of frames of this process"):
        other.write_frame(tmp_path, overwrite=True)  # while the first series goes on
    sim.end_frames(tmp_path)
    with pytest.raises(ValueError, match="holds the output of an earlier run"):
        other.write_frame(tmp_path)
    for truthy_text in ("False", "no", 1):  # not a bool: refused, not taken as true (it would remove the run)
        with pytest.raises(TypeError, match="overwrite is True or False"):
            other.write_frame(tmp_path, overwrite=truthy_text)
    assert ((tmp_path / "series.pvd").read_bytes(), pathlib.Path(first).read_bytes()) == before
    # ... unless asked: that run's files are set aside, so the series is this one's alone.
    (tmp_path / "notes.txt").write_text("mine")
    assert pathlib.Path(other.write_frame(tmp_path, overwrite=True)).name == "frame_000000.vtp"
    assert not pathlib.Path(second).exists() and (tmp_path / "notes.txt").read_text() == "mine"
    assert len(list(ET.parse(tmp_path / "series.pvd").getroot().iter("DataSet"))) == 1
    with pytest.raises(ValueError, match="a folder is needed"):
        sim.write_frame("")
    with pytest.raises(ValueError, match="write_frame: dir: a path holds no NUL byte"):
        sim.write_frame("a\0b")


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_series_holds_its_folder_and_replaces_an_earlier_run_only_as_it_ends(pile, tmp_path, monkeypatch):
    out = tmp_path / "out"
    scene = tmp_path / "pile.yaml"
    scene.write_text(json.dumps(pile))
    run = subprocess.run([str(PROGRAM), "run", str(scene), "--backend", "cpu", "--duration", "0.01",
                          "--quiet", "--out", str(out), "--set", "output.vtk.every=2"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    earlier = _tree(out)
    assert "series.pvd" in earlier and "summary.json" in earlier
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    # A first frame that fails: the earlier run goes back where it was
    # (nothing took its place; it had stayed hidden aside), and the folder
    # is let go.
    monkeypatch.setenv("MARBLES_FAULT_TRUNCATE", "series.pvd")
    with pytest.raises(marbles.RuntimeFailure, match="left incomplete"):
        sim.write_frame(out, overwrite=True)
    monkeypatch.delenv("MARBLES_FAULT_TRUNCATE")
    assert not list(out.glob(".earlier-run-*")) and not (out / ".marbles-run.lock").exists()
    assert _tree(out) == earlier
    # While the series runs, the earlier run lies aside and the folder is the series' alone.
    sim.write_frame(out, overwrite=True)
    sim.step(2)
    sim.write_frame(out)
    (aside,) = out.glob(".earlier-run-*")
    assert _tree(aside) == earlier
    for command in (run.args + ["--overwrite"], [str(PROGRAM), "render", str(out)]):
        refused = subprocess.run(command, capture_output=True, text=True)
        assert refused.returncode == 2 and "is being written by another marbles command" in refused.stderr, command
    with pytest.raises(marbles.SceneError, match="another series of frames of this process"):
        marbles.Simulation.from_dict(pile, backend="cpu").write_frame(out, overwrite=True)
    # Its end removes the earlier run and lets the folder go.
    sim.end_frames()
    sim.end_frames(out)  # no series there: no error
    assert not list(out.glob(".earlier-run-*")) and not (out / ".marbles-run.lock").exists()
    assert sorted(_tree(out)) == ["frames/frame_000000.vtp", "frames/frame_000001.vtp", "series.pvd"]
    with pytest.raises(ValueError, match="holds the output of an earlier run"):
        sim.write_frame(out)  # its own ended series, now an earlier run's output
    # The simulation's end ends its series too.
    other = marbles.Simulation.from_dict(pile, backend="cpu")
    other.write_frame(out, overwrite=True)
    assert list(out.glob(".earlier-run-*"))
    del other
    gc.collect()
    assert not list(out.glob(".earlier-run-*")) and not (out / ".marbles-run.lock").exists()
    rendered = subprocess.run(run.args + ["--overwrite"], capture_output=True, text=True)
    assert rendered.returncode == 0, rendered.stderr


def test_reference_says_none_where_the_run_gives_no_figure_and_refuses_a_nan_state():
    # A finest reference's error comes from the study: None here, as
    # summary.json's null (it was NaN). A state written non-finite through a
    # view is refused by reference() and contacts() too, not measured.
    finest = marbles.Simulation(SCENES / "validation" / "resting_stack.yaml", backend="cpu")
    finest.step(3)
    r = finest.reference()
    assert r["kind"] == "finest" and r["error"] is None
    sim = marbles.Simulation(SCENES / "validation" / "momentum_free.yaml", backend="cpu")
    sim.step(5)
    r = sim.reference()
    assert r["kind"] == "momentum" and r["error"] is not None and math.isfinite(r["error"])
    assert all(math.isfinite(v) for v in r["measured"])
    sim.velocities[0] = [np.nan, 0, 0]
    for reader in (sim.reference, sim.contacts):
        with pytest.raises(ValueError, match=r"velocities\[0\] is not finite"):
            reader()


def test_run_until_rounds_as_the_program_and_each_pipeline_names_its_threads(pile):
    # A time of 2.5 steps is 3 steps, as the program rounds a duration
    # (run(until=duration) took 2 where run() took 3: Python's round(2.5) is 2).
    short = {"time.dt": 0.002, "time.duration": 0.005}
    whole = marbles.Simulation.from_dict(pile, backend="cpu", set=short).run()
    until = marbles.Simulation.from_dict(pile, backend="cpu", set=short)
    until.run(until=until.duration)
    assert whole.steps == until.steps == 3
    assert marbles.Simulation.from_dict(pile, backend="cpu").run(until=0.0035).steps == 4  # 3.5 steps of 1 ms
    # The pipeline names the simulation's own threads, not the last one made.
    one = marbles.Simulation.from_dict(pile, backend="cpu", threads=1)
    marbles.Simulation.from_dict(pile, backend="cpu", threads=3)
    assert "on the CPU, 1 thread)" in one.pipeline


def test_a_simulation_is_not_copied_by_copy_or_pickle(pile):
    # copy.copy handed back the same simulation under two names (stepping
    # one stepped the other); it and pickling say what to use instead.
    import copy
    import pickle
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    for make in (copy.copy, copy.deepcopy, pickle.dumps):
        with pytest.raises(TypeError, match="checkpoint\\(\\) writes the state"):
            make(sim)


def test_warnings_and_repr(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    assert "64 spheres" in repr(sim) and "pile" in repr(sim)
    assert sim.material_names == ["glass"]


def test_renumbered_scene_keeps_the_scene_numbering(pile, tmp_path):
    # solver.renumber: the step numbers the spheres its own way; Python sees
    # the scene's numbering, as read-only copies, and writes by assignment.
    pile["particles"] = [{"random": {"count": 60, "min": [0.01, 0.01, 0.01], "max": [0.09, 0.09, 0.25],
                                     "radius": {"uniform": [0.006, 0.009]}, "seed": 4}}]
    pile["solver"] = {"renumber": 3}
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    radii = sim.radii.copy()
    sim.step(10)
    assert np.array_equal(sim.radii, radii)  # each sphere keeps its index
    x = sim.positions
    assert not x.flags.writeable
    with pytest.raises(ValueError):
        x[0, 0] = 1.0
    v = sim.velocities.copy()
    v[5] = [0, 0, 1]
    sim.velocities = v
    assert np.array_equal(sim.velocities[5], np.array([0, 0, 1], dtype=v.dtype))
    sim.step(2)  # between two numberings (at the start of steps 10 and 13)
    path = tmp_path / "r.mck"
    sim.checkpoint(path)
    sim.step(7)
    again = marbles.Simulation.restart(path, backend="cpu")
    again.step(7)
    assert np.array_equal(sim.positions, again.positions)
    assert np.array_equal(sim.velocities, again.velocities)


def test_steps_kept_unswept_are_counted_as_marbles_run_counts_them(tmp_path):
    # A sphere struck at 100 m/s with dt = 1/60 s leaves past what even the
    # watchdog's finest substep sweeps: the step is kept and counted, in the
    # Python summary as in summary.json, and through a checkpoint.
    scene = {"format": 1, "time": {"duration": 0.05, "dt": 1 / 60},
             "effects": ["collisions", "restitution"],
             "materials": {"a": {"density": 1000, "restitution": 0.5}},
             "particles": [{"list": {"positions": [[1.38, 0, 0], [1.5, 0, 0], [1.7, 0.02, 0]], "radius": 0.05,
                                     "velocities": [[100, 0, 0], [0, 0, 0], [0, 0, 0]]}}]}
    path = tmp_path / "struck.yaml"
    path.write_text(json.dumps(scene))
    out = tmp_path / "run"
    subprocess.run([PROGRAM, "run", str(path), "--out", str(out), "--summary-only", "--quiet", "--backend", "cpu"],
                   check=True, capture_output=True)
    summary = json.loads((out / "summary.json").read_text())
    sim = marbles.Simulation(path, backend="cpu")
    sim.step(1)
    sim.checkpoint(tmp_path / "one.mck")
    sim.run()
    assert summary["unswept_steps"] >= 1
    assert sim.summary()["unswept_steps"] == summary["unswept_steps"]
    assert sim.summary()["rollbacks"] == summary["rollbacks"]
    assert sim.unswept_steps == summary["unswept_steps"] and sim.rollbacks == summary["rollbacks"]
    again = marbles.Simulation.restart(tmp_path / "one.mck", scene=path, backend="cpu")
    again.run()
    assert again.summary()["unswept_steps"] == summary["unswept_steps"]


def test_spheres_written_into_each_other_are_pushed_apart(pile):
    # The watchdog's overlap rule waits a step after an edit: spheres written onto one spot are pushed apart
    # over the next steps, as if a scene had placed them so, not taken for a blow-up.
    scene = dict(pile, effects=["collisions"], walls=[])
    scene["particles"] = [{"list": {"positions": [[0.02 * k, 0, 0] for k in range(20)], "radius": 0.01}}]
    for when in (0, 1):
        sim = marbles.Simulation.from_dict(scene, backend="cpu")
        sim.step(when)
        sim.positions = np.zeros((20, 3))
        sim.step(100)
        assert sim.rollbacks == 0
        assert sim.max_overlap < 0.01
