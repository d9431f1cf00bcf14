# tests/python/test_errors.py — bad input raises marbles.SceneError with the
# place it names (file, line, column, key), as the command line says it.
import functools
import json
import math
import os
import pathlib
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import marbles
from conftest import HAS_CUDA, PROGRAM, SCENES


def test_file_error_names_line_column_and_key(tmp_path):
    scene = tmp_path / "bad.yaml"
    scene.write_text("time: {duration: 1, dt: 1e-3}\n"
                     "materials:\n"
                     "  glass: {density: 2500, restitution: 1.3}\n"
                     "particles:\n"
                     "  - list: {positions: [[0, 0, 1]], radius: 0.1}\n")
    with pytest.raises(marbles.SceneError) as caught:
        marbles.Simulation(scene)
    e = caught.value
    assert (e.file, e.line, e.key) == (str(scene), 3, "materials.glass.restitution")
    assert e.column > 0 and "within [0, 1]" in e.message
    # the same text as marbles check prints
    cli = subprocess.run([PROGRAM, "check", str(scene)], capture_output=True, text=True)
    assert cli.returncode == 2 and str(e) in cli.stderr


def test_dict_error_names_the_key_path(pile):
    pile["materials"]["glass"]["friction"] = -1
    with pytest.raises(marbles.SceneError) as caught:
        marbles.Simulation.from_dict(pile)
    e = caught.value
    assert (e.file, e.line, e.column, e.key) == ("<dict>", 0, 0, "materials.glass.friction")
    assert str(e).startswith("<dict>: materials.glass.friction: ")


@pytest.mark.parametrize("edit, key", [
    (lambda s: s["time"].update(dt=float("nan")), "time.dt"),
    (lambda s: s["particles"][0]["lattice"].update(spacing="wide"), "particles[0].lattice.spacing"),
    (lambda s: s.update(gravity=[0, 0]), "gravity"),
    (lambda s: s.update(efects=[]), "efects"),
    (lambda s: s["walls"][0]["box"].update(max=np.array([0.1, 0.1, np.inf])), "walls[0].box.max"),
    (lambda s: s["time"].update(duration=10**400), "time.duration"),  # past any double
    (lambda s: s["materials"]["glass"].update(density=-10**400), "materials.glass.density"),
])
def test_dict_values_are_checked(pile, edit, key):
    edit(pile)
    with pytest.raises(marbles.SceneError) as caught:
        marbles.Simulation.from_dict(pile)
    assert caught.value.key.startswith(key) and caught.value.line == 0


def test_set_errors_name_the_override(pile):
    with pytest.raises(marbles.SceneError) as caught:
        marbles.Simulation.from_dict(pile, set={"time.dt": -1})
    assert caught.value.file == "--set time.dt=-1" and caught.value.key == "time.dt"


def test_missing_file_and_bad_arguments(tmp_path, pile):
    with pytest.raises(marbles.SceneError) as caught:
        marbles.Simulation(tmp_path / "none.yaml")
    assert "none.yaml" in caught.value.file
    with pytest.raises(marbles.SceneError, match="backend"):
        marbles.Simulation.from_dict(pile, backend="gpu")
    with pytest.raises(marbles.SceneError):
        marbles.Simulation.from_dict([1, 2])
    with pytest.raises(marbles.SceneError, match="xyzr"):
        marbles.pairs(np.zeros((3, 3)))
    with pytest.raises(marbles.SceneError, match=r"xyzr\[1\]"):
        marbles.pairs(np.array([[0, 0, 0, 1], [0, 0, np.nan, 1]], np.float32))


@pytest.mark.skipif(HAS_CUDA, reason="a CUDA device is present")
def test_cuda_without_a_device_is_a_runtime_failure(pile):
    with pytest.raises(marbles.RuntimeFailure, match="no CUDA device"):
        marbles.Simulation.from_dict(pile, backend="cuda")


def test_one_thread_steps_a_simulation_at_a_time(pile):
    # step() lets the GIL go; a second thread stepping or changing the same
    # simulation meanwhile is refused with RuntimeFailure, never raced (which
    # crashed the interpreter), and no step is lost or doubled.
    import threading
    sim = marbles.Simulation.from_dict(pile)
    done, refused = [0], []

    def stepper():
        for _ in range(300):
            try:
                sim.step()
                done[0] += 1
            except marbles.RuntimeFailure as e:
                refused.append(str(e))

    threads = [threading.Thread(target=stepper) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert done[0] + len(refused) == 1200
    assert sim.steps == done[0]
    assert all("stepping in another thread" in r for r in refused)


def test_a_path_with_a_nul_byte_is_refused_not_cut(pile, tmp_path):
    # The program reads a path up to a NUL byte: "ball.yaml\0junk" loaded
    # ball.yaml, and a study ran it.
    scene = str(SCENES / "validation" / "bouncing_ball.yaml")
    for call in (lambda: marbles.Simulation(scene + "\0junk"),
                 lambda: marbles.Simulation.restart(str(tmp_path / "c.mck") + "\0x", scene=scene),
                 lambda: marbles.study(scene + "\0x", vary={"time.dt": [1e-3, 5e-4]}, out=tmp_path / "s"),
                 lambda: marbles.Simulation(scene).checkpoint(str(tmp_path / "c.mck") + "\0x")):
        with pytest.raises(ValueError, match="a path holds no NUL byte"):
            call()
    assert not (tmp_path / "s").exists() and not list(tmp_path.iterdir())


def test_readers_in_another_thread_wait_for_no_step_and_never_race_it(pile):
    # contacts(), kinetic_energy(), the arrays, summary() and reference()
    # from a thread while another steps are refused (RuntimeFailure), not
    # run beside the step (which crashed the interpreter, most often with
    # solver.renumber, whose host copy the readers make); len() and the
    # pipeline are read. The readers leave the run's bits as they were.
    import threading
    for renumber in (0, 1):
        sim = marbles.Simulation.from_dict(pile, backend="cpu", threads=1, set={"solver.renumber": renumber})
        stepper = threading.Thread(target=sim.step, args=(400,))
        stepper.start()
        refused = []
        while stepper.is_alive():
            for reader in (sim.contacts, sim.kinetic_energy, lambda: sim.positions, sim.summary, sim.reference,
                           lambda: sim.velocities.copy(), lambda: len(sim), lambda: sim.pipeline):
                try:
                    reader()
                except marbles.RuntimeFailure as e:
                    refused.append(str(e))
        stepper.join()
        assert sim.steps == 400
        assert refused and all("stepping in another thread" in r for r in refused)
        # The readers left the run as it was: the same bits as a run no one read.
        alone = marbles.Simulation.from_dict(pile, backend="cpu", threads=1, set={"solver.renumber": renumber})
        alone.step(400)
        assert np.array_equal(sim.positions, alone.positions) and np.array_equal(sim.velocities, alone.velocities)
        assert sim.kinetic_energy() == alone.kinetic_energy()


def test_a_step_left_running_at_the_end_of_a_script_ends_quietly(pile, tmp_path):
    # A daemon thread still inside step() as the interpreter ends waits out
    # the end (the process ends with the script's status), where taking
    # the GIL back aborted the process ("terminate called without an
    # active exception"); its simulation is not reported as leaked.
    # So do pairs() called again and again in daemon threads; and a step on
    # the main thread in an atexit hook that runs after the module's (it had
    # parked there for ever).
    script = tmp_path / "left.py"
    script.write_text(
        "import atexit, json, sys, threading, time\n"
        "atexit.register(lambda: print('last step', sim.step(3).steps, flush=True))\n"
        "import marbles, numpy as np\n"
        f"sim = marbles.Simulation.from_dict(json.loads({json.dumps(json.dumps(pile))}), threads=1)\n"
        "threading.Thread(target=sim.step, args=(10**9,), daemon=True).start()\n"
        "other = marbles.Simulation.from_dict(json.loads(" + repr(json.dumps(pile)) + "), threads=1)\n"
        "def loop():\n"
        "    while True:\n"
        "        other.step()\n"  # a step that ends, and takes the GIL back, again and again
        "threading.Thread(target=loop, daemon=True).start()\n"
        "xyzr = np.random.default_rng(1).uniform(0, 1, (20000, 4)).astype(np.float32)\n"
        "xyzr[:, 3] = 0.004\n"
        "def search():\n"
        "    while True:\n"
        "        marbles.pairs(xyzr)\n"
        "for _ in range(2):\n"
        "    threading.Thread(target=search, daemon=True).start()\n"
        "time.sleep(0.5)\n"
        "print('ending', flush=True)\n"
        "sim = marbles.Simulation.from_dict(json.loads(" + repr(json.dumps(pile)) + "), threads=1)\n"
        "sys.exit(3)\n")
    for _ in range(3):
        ended = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                               env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
        assert ended.returncode == 3, ended.stderr
        assert ended.stdout == "ending\nlast step 3\n", ended.stdout
        assert "leaked" not in ended.stderr and "terminate" not in ended.stderr, ended.stderr


def test_a_signal_handler_reads_the_simulation_it_interrupts(pile):
    # Python runs a signal handler in the stepping thread, between two steps
    # (where step() looks for Ctrl-C): there it may read the simulation
    # (readers had been refused as "stepping in another thread"), but not
    # step or change it.
    import signal
    sim = marbles.Simulation.from_dict(pile, backend="cpu", threads=1)
    read, refused = [], []

    def handler(*_):
        read.append(sim.kinetic_energy())
        read.append(len(sim.contacts()["pairs"]))
        if len(read) >= 6:
            try:
                sim.step(1)
            except marbles.RuntimeFailure as e:
                refused.append(str(e))
            raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, 0.15, 0.15)
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.step(10**9)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert len(read) >= 6 and all(math.isfinite(v) for v in read)
    assert refused and "stepping in this thread (a signal handler during step())" in refused[0]
    done = sim.steps
    sim.step(2)  # the simulation goes on
    assert sim.steps == done + 2


def test_a_study_stops_on_an_interrupt_and_leaves_the_earlier_one_whole(tmp_path):
    # Ctrl-C reaching the Python process alone (a notebook's interrupt) ran
    # on until every run of the study had run. It now ends the running run
    # and raises KeyboardInterrupt; the earlier study in the folder is whole.
    import signal
    import threading
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    out = tmp_path / "study"
    marbles.study(scene, vary={"time.dt": [1e-3, 5e-4]}, out=out)
    earlier = {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    long_runs = {"time.dt": [2e-5, 1e-5, 5e-6]}  # each run takes many seconds here
    started = threading.Event()

    def press():  # Ctrl-C, again every 0.3 s, until the study returns
        started.wait()
        while not stopping.wait(0.3):
            os.kill(os.getpid(), signal.SIGINT)

    stopping = threading.Event()
    presser = threading.Thread(target=press)
    presser.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            started.set()
            marbles.study(scene, vary=long_runs, set={"time.duration": 60}, out=out)
    finally:
        stopping.set()
        presser.join()
    now = {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()
           if not str(p.relative_to(out)).startswith(".runs-")}
    assert now == earlier
    (staging,) = out.glob(".runs-*")  # the stopped study's: one run started, none after it
    assert [p.name for p in staging.iterdir() if p.suffix == ".log"] == ["0.log"]
    ps = subprocess.run(["ps", "-eo", "args"], capture_output=True, text=True).stdout
    assert str(staging) not in ps, "the stopped run was left running"


def test_a_long_step_stops_on_an_interrupt(pile):
    # A pending SIGINT (Ctrl-C) ends step(n) between two steps with
    # KeyboardInterrupt; the steps done are kept and the simulation goes on.
    import signal
    import threading
    sim = marbles.Simulation.from_dict(pile)
    stepping = threading.Event()

    # Ctrl-C, pressed again every 0.3 s until the step ends (a run of this
    # suite once waited on one signal for minutes; none was seen lost since).
    def press():
        while not stepping.wait(0.3):
            os.kill(os.getpid(), signal.SIGINT)

    presser = threading.Thread(target=press)
    presser.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.step(10**9)
    finally:
        stepping.set()
        presser.join()
    done = sim.steps
    assert 0 < done < 10**9
    sim.step(2)
    assert sim.steps == done + 2


def test_counts_are_whole_numbers(pile):
    sim = marbles.Simulation.from_dict(pile)
    for n, error in ((2.5, ValueError), ("3", TypeError), (True, TypeError), (None, TypeError), (-1, ValueError),
                     (float("nan"), ValueError)):
        with pytest.raises(error, match="step: n"):
            sim.step(n)
    assert sim.steps == 0  # nothing was rounded into steps
    sim.step(np.int64(2)).step(3.0).step(1e1)
    assert sim.steps == 15
    for every, error in ((0.5, ValueError), (0, ValueError), ("2", TypeError)):
        with pytest.raises(error, match="run: every"):
            sim.run(until=1.0, every=every)
    for until, error in ((float("nan"), ValueError), (-1.0, ValueError), ("1", TypeError), (10**400, ValueError)):
        with pytest.raises(error, match="run: until"):
            sim.run(until=until)
    with pytest.raises(TypeError, match="run: callback"):
        sim.run(until=1.0, callback=5)
    # A callback that cannot take the simulation is refused before the first step.
    for callback in (lambda: None, lambda s, t: None, lambda *, s: None):
        with pytest.raises(TypeError, match="run: callback: is called with one argument"):
            sim.run(until=1.0, callback=callback)
    assert sim.steps == 15
    seen = []
    sim.run(until=sim.time + 2 * sim.dt, callback=lambda s, extra=1, *rest: seen.append(extra))
    sim.run(until=sim.time + sim.dt, callback=lambda *a: seen.append(len(a)))
    assert seen == [1, 1, 1] and sim.steps == 18

    def with_extra(s, extra):
        seen.append(extra)

    @functools.wraps(with_extra)
    def wrapped(s):  # called as it is, not as the function it wraps
        return with_extra(s, 7)

    sim.run(until=sim.time + sim.dt, callback=wrapped)
    assert seen[-1] == 7 and sim.steps == 19
    # A callback's NumPy False stops the run as False does.
    sim.run(until=sim.time + 10 * sim.dt, callback=lambda s: np.False_, every=2)
    assert sim.steps == 21
    # threads: 0 (the default count) or 1 to 4096, a whole number.
    for threads, error in ((-7, ValueError), (10**6, ValueError), (1.5, ValueError), ("2", TypeError)):
        with pytest.raises(error, match="threads"):
            marbles.Simulation.from_dict(pile, threads=threads)
    # Held to the run's substeps limit (the program's own, sim/limits.hpp), as `marbles run --duration` is:
    # no endless call.
    limit = marbles._marbles.substeps_limit()
    assert limit > 0
    for call in (lambda: sim.step(np.uint64(2**64 - 1)), lambda: sim.step(np.float32(limit * 10)),
                 lambda: sim.step(int(limit // sim.substeps) + 1), lambda: sim.run(until=1e20)):
        with pytest.raises(ValueError, match=re.escape(f"more than the limit {limit:.0e}")):
            call()
    assert sim.steps == 21
    # A 0-d array is its one value, in a scene dict and in an override.
    zero_d = dict(pile)
    zero_d["time"] = dict(pile["time"], dt=np.array(pile["time"]["dt"]))
    assert marbles.Simulation.from_dict(zero_d, set={"solver.iterations": np.array(5)}).dt == pile["time"]["dt"]


def test_each_simulation_steps_on_its_own_threads(pile):
    # OpenMP's thread count is the process's: a simulation made later with
    # another count must not change the count an earlier one steps with.
    ctypes = pytest.importorskip("ctypes")
    try:
        gomp = ctypes.CDLL("libgomp.so.1")
    except OSError:
        pytest.skip("no libgomp to ask")
    one = marbles.Simulation.from_dict(pile, backend="cpu", threads=1)
    two = marbles.Simulation.from_dict(pile, backend="cpu", threads=2)
    one.step(1)
    assert gomp.omp_get_max_threads() == 1
    two.step(1)
    assert gomp.omp_get_max_threads() == 2


def test_array_and_study_argument_errors(pile, tmp_path):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")  # host views
    with pytest.raises(ValueError, match=r"^velocities: expected shape"):
        sim.velocities = np.zeros((2, 3))
    bad = np.zeros((len(sim), 3))
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"^angular_velocities\[1\] is not finite"):
        sim.angular_velocities = bad
    # Finite, but squared by the step (energies) past float's range: refused as a scene's vectors are.
    before = sim.velocities.copy()
    huge = np.zeros((len(sim), 3))
    huge[2] = [3e38, 0, 0]
    with pytest.raises(ValueError, match=r"^velocities\[2\] is too large for float precision: its squared length "
                                         r"overflows; the state is unchanged"):
        sim.velocities = huge
    huge[2] = [2e19, 0, 0]  # each component finite, the square past 3.4e38
    with pytest.raises(ValueError, match=r"^positions\[2\] is too large"):
        sim.positions = sim.positions + huge
    np.testing.assert_array_equal(sim.velocities, before)
    huge[2] = [1e18, 0, 0]  # its square fits: taken
    sim.velocities = huge
    assert sim.velocities[2, 0] == np.float32(1e18)
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    for repeats, error in ((0, ValueError), (-3, ValueError), (1.5, ValueError), (float("nan"), ValueError),
                           (float("inf"), ValueError), (2**40, ValueError), (None, TypeError), ("2", TypeError)):
        with pytest.raises(error, match="repeats"):
            marbles.study(scene, vary={"time.dt": [1e-3]}, repeats=repeats, out=tmp_path)
    # pairs: a margin past the precision's range, or an unknown backend, whatever the algorithm.
    xyzr = np.random.default_rng(1).random((20, 4)).astype(np.float32)
    for algorithm in ("brute", "home"):
        with pytest.raises(marbles.SceneError, match="margin: out of range for float precision"):
            marbles.pairs(xyzr, algorithm=algorithm, margin=1e39)
        with pytest.raises(marbles.SceneError, match="backend: must be auto, cpu or cuda"):
            marbles.pairs(xyzr, algorithm=algorithm, backend="gpu")
    with pytest.raises(ValueError, match="comma outside brackets"):
        marbles.study(scene, vary={"time.dt": ["1e-3,2e-3"]}, out=tmp_path)


def test_checkpoint_paths_that_are_no_file(pile, tmp_path):
    sim = marbles.Simulation.from_dict(pile)
    with pytest.raises(marbles.SceneError, match="is a folder, not a checkpoint"):
        marbles.Simulation.restart(tmp_path, scene=pile)
    for path in ("", "a\x00b"):
        with pytest.raises(ValueError, match="a path is needed|a path holds no NUL byte"):
            sim.checkpoint(path)
    # A damaged record of the scene beside a checkpoint.
    ck = tmp_path / "c.mck"
    sim.checkpoint(ck)
    assert marbles.Simulation.restart(ck).steps == 0  # premise: it restarts as written
    for text in ("{bad", "[1, 2]", "{}", '{"scene": 5, "set": []}', '{"dict": "not json", "set": []}',
                 '{"dict": "{}", "name": 5, "set": []}', '{"scene": "a.yaml", "set": [5]}',
                 # JSON nested past Python's depth, the record or its scene dict (a RecursionError before)
                 "[" * 100000 + "]" * 100000, json.dumps({"dict": "[" * 100000 + "]" * 100000, "set": []})):
        (tmp_path / "c.mck.scene.json").write_text(text)
        with pytest.raises(marbles.SceneError, match="not the record of a scene"):
            marbles.Simulation.restart(ck)
    # A record whose scene dict is JSON but no scene: the error names the record, not "<dict>".
    for text in ('{"dict": "null", "set": []}', '{"dict": "{\\"time\\": 5}", "set": []}'):
        (tmp_path / "c.mck.scene.json").write_text(text)
        with pytest.raises(marbles.SceneError) as caught:
            marbles.Simulation.restart(ck)
        assert caught.value.file == str(ck) + ".scene.json", str(caught.value)
    # The record's place a folder: nothing written, a RuntimeFailure naming it; restart says the same.
    (tmp_path / "d.mck.scene.json").mkdir()
    with pytest.raises(marbles.RuntimeFailure, match=r"d\.mck\.scene\.json: it is not a file; nothing was written"):
        sim.checkpoint(tmp_path / "d.mck")
    assert not (tmp_path / "d.mck").exists()
    with pytest.raises(marbles.RuntimeFailure, match=r"cannot read .*d\.mck\.scene\.json"):
        marbles.Simulation.restart(tmp_path / "d.mck")


def test_dicts_that_hold_themselves_or_nest_too_deep(pile):
    looped = dict(pile)
    looped["materials"] = {"glass": {"density": 2500}}
    looped["materials"]["glass"]["again"] = looped
    deep = dict(pile)
    nest = deep["reference"] = {}
    for _ in range(50000):
        nest["x"] = {}
        nest = nest["x"]
    for scene in (looped, deep):
        with pytest.raises(marbles.SceneError, match="holds itself, or nests deeper"):
            marbles.Simulation.from_dict(scene)
    # The same in an override's value (a RecursionError before), and overrides given as bytes, which
    # iterated are numbers ("--set 116: expected key.path=value" before).
    value = [1e-3]
    value.append(value)
    with pytest.raises(marbles.SceneError, match=r"set: time\.dt: the value holds itself, or nests deeper"):
        marbles.Simulation.from_dict(pile, set={"time.dt": value})
    for given in (b"time.dt=5e-4", bytearray(b"time.dt=5e-4")):
        with pytest.raises(TypeError, match="set: a dict of key -> value, or a list of 'key=value' texts"):
            marbles.Simulation.from_dict(pile, set=given)


def test_a_study_into_a_folder_it_cannot_make_is_a_runtime_failure(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(marbles.RuntimeFailure):
        marbles.study(SCENES / "validation" / "bouncing_ball.yaml", vary={"time.dt": [1e-3]}, out=blocker / "study")


def test_a_checkpoint_by_its_bare_name_and_never_over_its_scene(pile, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sim = marbles.Simulation.from_dict(pile)
    sim.step(2)
    sim.checkpoint("state.mck")  # no folder in the name: written where the process is
    assert marbles.Simulation.restart("state.mck").steps == 2
    scene = tmp_path / "ball.yaml"
    scene.write_bytes((SCENES / "validation" / "bouncing_ball.yaml").read_bytes())
    before = scene.read_bytes()
    ball = marbles.Simulation(scene)
    for path in (scene, "./ball.yaml", "ball.yaml"):
        with pytest.raises(ValueError, match="is this simulation's scene file"):
            ball.checkpoint(path)
    assert scene.read_bytes() == before


def test_a_checkpoint_and_its_record_are_written_together(pile, tmp_path, monkeypatch):
    sim = marbles.Simulation.from_dict(pile)
    ck = tmp_path / "c.mck"
    sim.checkpoint(ck)
    old = ck.read_bytes(), (tmp_path / "c.mck.scene.json").read_bytes()
    sim.step(3)
    # The record left incomplete (the full-disk hook): the new checkpoint is not put beside the old record.
    monkeypatch.setenv("MARBLES_FAULT_TRUNCATE", "scene.json")
    with pytest.raises(marbles.RuntimeFailure, match="left incomplete"):
        sim.checkpoint(ck)
    with pytest.raises(marbles.RuntimeFailure, match="left incomplete"):
        sim.checkpoint(tmp_path / "new.mck")
    monkeypatch.delenv("MARBLES_FAULT_TRUNCATE")
    assert (ck.read_bytes(), (tmp_path / "c.mck.scene.json").read_bytes()) == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.mck", "c.mck.scene.json"]
    assert marbles.Simulation.restart(ck).steps == 0


def test_frames_of_one_folder_however_it_is_named(pile, tmp_path, monkeypatch):
    sim = marbles.Simulation.from_dict(pile)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "elsewhere").mkdir()
    written = []
    for name in ("o", "o/", "./o"):
        written.append(sim.write_frame(name))
        sim.step()
    monkeypatch.chdir(tmp_path / "elsewhere")  # a later chdir moves nothing
    written.append(sim.write_frame(tmp_path / "o"))
    assert [pathlib.Path(p).name for p in written] == [f"frame_{k:06d}.vtp" for k in range(4)]
    assert all(pathlib.Path(p).parent == tmp_path / "o" / "frames" for p in written)
    listed = re.findall(r'file="([^"]+)"', (tmp_path / "o" / "series.pvd").read_text())
    assert listed == [f"frames/frame_{k:06d}.vtp" for k in range(4)]
    assert all((tmp_path / "o" / f).is_file() for f in listed)
    assert not (tmp_path / "elsewhere" / "o").exists()


def test_a_frame_is_not_left_where_its_series_cannot_be_written(pile, tmp_path, monkeypatch):
    sim = marbles.Simulation.from_dict(pile)
    (tmp_path / "series.pvd").mkdir()
    with pytest.raises(marbles.RuntimeFailure, match=r"series\.pvd: it is a folder"):
        sim.write_frame(tmp_path)
    (tmp_path / "series.pvd").rmdir()
    monkeypatch.setenv("MARBLES_FAULT_TRUNCATE", "series.pvd")
    with pytest.raises(marbles.RuntimeFailure, match="left incomplete"):
        sim.write_frame(tmp_path)
    monkeypatch.delenv("MARBLES_FAULT_TRUNCATE")
    assert not list(tmp_path.rglob("*.vtp")) and not (tmp_path / "series.pvd").exists()
    first = sim.write_frame(tmp_path)  # the series goes on at frame 0, none skipped
    assert pathlib.Path(first).name == "frame_000000.vtp"


def test_string_overrides_are_the_strings_given(pile, tmp_path):
    ball = SCENES / "validation" / "bouncing_ball.yaml"
    for name in ("run #2", "&a x", "a: b", "x\ny", " lead", "[1]", "", "null", "~", "...", "run \U0001F600",
                 "plain_name-2.0", "my run", "true"):
        assert marbles.Simulation(ball, set={"name": name}).name == name, name
        assert marbles.Simulation.from_dict(pile, set={"name": name}).name == name, name
    # Numbers and words given as strings still read as the scene reads them.
    assert marbles.Simulation(ball, set={"time.dt": "5e-4", "solver.precision": "double"}).dt == 5e-4
    # A list's YAML text is a list only as set=["key=..."]; as a dict's string it is refused, not changed.
    with pytest.raises(marbles.SceneError, match="expected a sequence"):
        marbles.Simulation(ball, set={"effects": "[gravity, walls]"})
    assert marbles.Simulation(ball, set=["effects=[gravity, walls]"]).name
    # A string the scene reads plainly is passed as the same text as --set gives it: a checkpoint of
    # marbles run restarts with the dict form of its overrides.
    out = tmp_path / "run"
    cli = subprocess.run([PROGRAM, "run", str(ball), "--backend", "cpu", "--quiet", "--summary-only", "--out", str(out),
                          "--duration", "0.02", "--set", "output.checkpoint={every: 10}", "--set", "name=my run"],
                         capture_output=True, text=True)
    assert cli.returncode == 0, cli.stderr
    resumed = marbles.Simulation.restart(out / "checkpoints" / "step_000010.mck", scene=ball,
                                         set={"output.checkpoint": {"every": 10}, "name": "my run"})
    assert resumed.steps == 10
    # A study's values are YAML text, as marbles study --vary takes them.
    rows = marbles.study(ball, vary={"gravity": ["[0, 0, -9.81]", "[0, 0, -5]"]}, set={"time.duration": 0.05},
                         out=tmp_path / "study")
    assert len(rows) == 2


def test_the_state_read_after_a_bad_write_is_refused(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")  # host views
    sim.velocities[0, 2] = np.nan
    with pytest.raises(ValueError, match=r"velocities\[0\] is not finite"):
        sim.kinetic_energy()
    with pytest.raises(ValueError, match=r"velocities\[0\] is not finite"):
        sim.summary()
    sim.velocities[0, 2] = 0
    assert np.isfinite(sim.kinetic_energy())
    for name in ("bogus", "positions", ""):
        with pytest.raises(ValueError, match="no state array"):
            sim._impl.view(name)
    with pytest.raises(ValueError, match="read-only"):
        sim._impl.assign("radius", np.zeros((len(sim), 3), dtype=np.float32))


def test_spheres_that_start_overlapping_are_a_warning(pile):
    scene = dict(pile)
    scene["particles"] = [{"list": {"positions": [[0.05, 0.05, 0.05], [0.05, 0.05, 0.05]], "radius": 0.01}}]
    with pytest.warns(UserWarning, match="1 pair\\(s\\) of spheres start overlapping"):
        marbles.Simulation.from_dict(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        marbles.Simulation.from_dict(pile)  # the pile's spheres start apart: no warning


def test_a_study_checks_every_run_before_the_first(tmp_path):
    scene = SCENES / "validation" / "bouncing_ball.yaml"
    for vary, backend, match in (({"nokey": [1]}, "auto", "unknown key 'nokey'"),
                                 ({"time.dt": [1e-3, -1]}, "auto", r"time\.dt: must be > 0.*study run time\.dt=-1"),
                                 ({"time.dt": [1e-3]}, "bad", "backend: expected one of auto, cpu, cuda")):
        with pytest.raises(marbles.SceneError, match=match):
            marbles.study(scene, vary=vary, backend=backend, out=tmp_path / "s")
        assert not (tmp_path / "s").exists()


def test_arguments_of_the_wrong_kind_are_named(pile, tmp_path):
    ball = SCENES / "validation" / "bouncing_ball.yaml"
    sim = marbles.Simulation.from_dict(pile, backend="cpu")  # host views
    cases = [
        (lambda: marbles.Simulation(ball, backend=None), TypeError, "backend: one of auto, cpu, cuda, got None"),
        (lambda: marbles.Simulation.from_dict(pile, backend=5), TypeError, "backend: one of"),
        (lambda: marbles.Simulation.from_dict(pile, name=5), TypeError, "name: the output folder's name"),
        (lambda: marbles.Simulation(ball, set=5), TypeError, "set: a dict of key -> value"),
        (lambda: marbles.Simulation(5), TypeError, "scene: a path"),
        (lambda: marbles.Simulation(""), marbles.SceneError, "scene: a scene file is needed"),
        (lambda: marbles.Simulation(os.fsdecode(b"ball\xff.yaml")), ValueError, "scene: a path of UTF-8 text"),
        (lambda: sim.write_frame(None), TypeError, "write_frame: dir: a path"),
        # NumPy's own errors named nothing: a ragged list, text, a dict, bool; an int past any float
        (lambda: marbles.pairs([[0, 0, 0, 1], [0, 0]]), TypeError, "xyzr: an array of numbers"),
        (lambda: marbles.pairs(["0", "0", "0", "a"]), TypeError, "xyzr: an array of numbers"),
        (lambda: marbles.pairs({"a": 1}), TypeError, "xyzr: an array of numbers"),
        (lambda: marbles.pairs(np.zeros((2, 4), dtype=bool)), TypeError, "xyzr: an array of numbers"),
        (lambda: marbles.pairs(np.zeros((2, 4)), margin=10**400), ValueError, "margin: too large a distance"),
        (lambda: setattr(sim, "velocities", "abc"), TypeError, "velocities: an array of numbers"),
        (lambda: setattr(sim, "positions", [[0, 0]] * len(sim)), ValueError, r"positions: expected shape"),
        (lambda: marbles.Simulation(ball, set={"name": "\ud800"}), marbles.SceneError, "set: name: not UTF-8 text"),
        (lambda: marbles.Simulation(ball, set=["name=\ud800"]), marbles.SceneError, "set: not UTF-8 text"),
        (lambda: marbles.Simulation(ball, set={"na\ud800me": 1}), marbles.SceneError, "set: not UTF-8 text"),
        (lambda: sim.checkpoint(3.5), TypeError, "checkpoint: path: a path"),
        (lambda: marbles.pairs(np.zeros((2, 4)), algorithm=None), TypeError, "algorithm: one of home"),
        (lambda: marbles.pairs(np.zeros((2, 4)), backend=None), TypeError, "backend: one of"),
        (lambda: marbles.pairs(np.zeros((2, 4)), margin="0.1"), TypeError, "margin: a distance"),
        (lambda: marbles.pairs(np.zeros((2, 4)), margin=True), TypeError, "margin: a distance"),
        (lambda: marbles.pairs(np.zeros((2, 4), dtype=complex)), TypeError, "xyzr: real numbers"),
        (lambda: setattr(sim, "positions", sim.positions.astype(complex)), TypeError, "position: real numbers"),
        (lambda: marbles.study(ball, vary={"time.dt": [1e-3]}, backend=None, out=tmp_path / "s"), TypeError,
         "study: backend: one of"),
        (lambda: sim.run(until=10**400), ValueError, "a number of 401 digits"),
        # a 0-d array is said as it is (the copy made it (1,)); a masked entry is not read as a number
        (lambda: marbles.pairs(np.array(3.0)), marbles.SceneError, "got shape ()"),
        (lambda: setattr(sim, "velocities", np.float64(0)), ValueError, f"expected shape ({len(sim)}, 3), got ()"),
        (lambda: marbles.pairs(np.ma.masked_array(np.zeros((2, 4)), mask=[[0, 0, 0, 0], [0, 0, 1, 0]])),
         ValueError, "xyzr: a masked array with 1 masked entry (the first at flat index 6)"),
        (lambda: setattr(sim, "positions", np.ma.masked_invalid(np.full((len(sim), 3), np.nan))), ValueError,
         f"positions: a masked array with {3 * len(sim)} masked entries (the first at flat index 0)"),
    ]
    for call, error, match in cases:
        with pytest.raises(error, match=re.escape(match)):
            call()
    # A masked array with nothing masked is its data.
    xyzr = np.array([[0, 0, 0, 1.0], [0, 0, 1.5, 1.0], [0, 0, 5, 1.0]])
    np.testing.assert_array_equal(marbles.pairs(np.ma.masked_array(xyzr, mask=False)), marbles.pairs(xyzr))
    # A bytes path is a path; the same scene as its str.
    assert marbles.Simulation(os.fsencode(str(ball))).name == marbles.Simulation(ball).name
    # A time already past is said, not passed over.
    sim.step(3)
    with pytest.raises(ValueError, match=r"run: until = 0\.001 s is before the simulation's time, 0\.003 s"):
        sim.run(until=0.001)
    sim.run(until=sim.time)  # the time it is at: nothing to do


def test_pairs_reads_any_byte_order_and_refuses_what_marbles_pairs_refuses():
    # A big-endian float64 array is float64: searched in double (it was cast to float, and this pair lost).
    near = np.array([[0, 0, 0, 0.5], [0.99999999999, 0, 0, 0.5]])
    assert marbles.pairs(near, backend="cpu").tolist() == [[0, 1]]
    assert marbles.pairs(near.astype(">f8"), backend="cpu").tolist() == [[0, 1]]
    # Centres whose squared distance overflows (the two overlap: they were found apart), and a
    # number too small for the precision, as `marbles pairs` refuses them in a CSV row.
    cases = [(np.array([[0, 0, 0, 1e20], [1e20, 0, 0, 1e20]], dtype=np.float32),
              r"^xyzr\[1\]: too large for float precision: the squared length of \(x, y, z\) overflows$"),
             (np.array([[0, 0, 0, 1e200], [1e200, 0, 0, 1e200]]),
              r"^xyzr\[1\]: too large for double precision: the squared length of \(x, y, z\) overflows$"),
             (np.array([[0, 0, 0, 1], [0, 1e-40, 0, 1]], dtype=np.float32),
              r"^xyzr\[1\]: y: too small for float precision, got 1e-40$"),
             # A radius of 0 (taken here, refused by the program) and a centre that is not finite.
             (np.array([[0, 0, 0, 1], [0, 0, 0.5, 0]]), r"^xyzr\[1\]: r: must be > 0, got 0$"),
             (np.array([[0, 0, 0, 1], [np.nan, 0, 0, 1]]), r"^xyzr\[1\]: x: must be a finite number, got nan$")]
    for xyzr, message in cases:
        with pytest.raises(marbles.SceneError, match=message):
            marbles.pairs(xyzr, backend="cpu")
        csv = "\n".join(",".join(repr(float(x)) for x in row) for row in xyzr)
        path = pathlib.Path(os.environ.get("TMPDIR", "/tmp")) / f"marbles_pairs_{os.getpid()}.csv"
        path.write_text(csv + "\n")
        precision = "double" if xyzr.dtype == np.float64 else "float"
        cli = subprocess.run([PROGRAM, "pairs", str(path), "--backend", "cpu", "--precision", precision],
                             capture_output=True, text=True)
        path.unlink()
        assert cli.returncode == 2, (xyzr, cli.stdout)  # the oracle: the program refuses them too


def test_a_value_written_through_a_view_is_checked_before_another_array_is_assigned(pile):
    sim = marbles.Simulation.from_dict(pile, backend="cpu")
    sim.positions[0, 2] = np.nan
    before = np.array(sim.velocities)
    with pytest.raises(ValueError, match=r"positions\[0\] is not finite"):
        sim.velocities = np.zeros((len(sim), 3))  # made the NaN known, and it went on unchecked
    np.testing.assert_array_equal(sim.velocities, before)
    with pytest.raises(ValueError, match=r"positions\[0\] is not finite"):
        sim.kinetic_energy()
    good = np.array(sim.positions)
    good[0, 2] = 0.5
    sim.positions = good  # the array that holds it, written whole: taken
    sim.velocities = np.zeros((len(sim), 3))
    sim.step()
    assert np.isfinite(sim.positions).all()
    # Finite as given, past float once cast: named as such (it said "is not finite").
    with pytest.raises(ValueError, match=r"^velocities\[0\] is too large for float precision; the state is unchanged"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # and no NumPy overflow warning beside it
            sim.velocities = np.full((len(sim), 3), 1e39)


def test_masked_entries_are_refused_wherever_a_scene_value_is_taken(pile, tmp_path):
    ball = SCENES / "bouncing_ball.yaml"
    g = np.ma.masked_array([0, 0, -9.81], mask=[0, 0, 1])  # read as 0: no gravity, and no word
    with pytest.raises(ValueError, match=r"gravity: a masked array with 1 masked entry"):
        marbles.Simulation(ball, backend="cpu", set={"gravity": g})
    scene = dict(pile)
    scene["gravity"] = g
    with pytest.raises(ValueError, match=r"gravity: a masked array with 1 masked entry"):
        marbles.Simulation.from_dict(scene, backend="cpu")
    with pytest.raises(ValueError, match=r"time.dt: a masked array with 1 masked entry"):
        marbles.study(ball, vary={"time.dt": np.ma.masked_array([1e-3, 5e-4], mask=[0, 1])}, out=tmp_path / "s")
    assert not (tmp_path / "s").exists()
    # Nothing masked: its data.
    full = np.ma.masked_array([0, 0, -9.81], mask=False)
    assert marbles.Simulation(ball, backend="cpu", set={"gravity": full}).name


def test_keys_of_a_dict_override_are_the_keys_given():
    ball = SCENES / "bouncing_ball.yaml"
    rubber = {"density": 1100, "restitution": 0.8, "friction": 0.5}
    for name in ("steel,glass", "'glass'", "null", "~", "a #b", "?x", "[x]", "k: v", "plain-2.0"):
        sim = marbles.Simulation(ball, backend="cpu", set={"materials": {"rubber": rubber, name: {"density": 2500}}})
        assert sim.material_names == ["rubber", name], name
    with pytest.raises(marbles.SceneError, match=r"set: materials: keys are strings, got 1"):
        marbles.Simulation(ball, backend="cpu", set={"materials": {"rubber": rubber, 1: {"density": 2500}}})
    # A string inside a list is the string given too: "walls,collisions" was two effects.
    with pytest.raises(marbles.SceneError, match="walls,collisions"):
        marbles.Simulation(ball, backend="cpu", set={"effects": ["gravity", "walls,collisions"]})
    assert marbles.Simulation(ball, backend="cpu", set={"effects": ["gravity", "walls"]}).name


def test_a_dict_nested_deeper_than_a_scene_file_may_be_is_refused_not_a_crash():
    # With Python's own bound raised, the dict reached the C++ loader, whose recursion overflowed the stack.
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(100000)
    try:
        x = 1
        for _ in range(20000):
            x = [x]
        with pytest.raises(marbles.SceneError, match=r"nested deeper than the YAML reader follows \(500 levels\)"):
            marbles.Simulation.from_dict({"format": 1, "gravity": x}, backend="cpu")
    finally:
        sys.setrecursionlimit(limit)


def test_a_name_or_study_folder_no_file_could_have_is_refused(pile, tmp_path, monkeypatch):
    for given in ({"name": "\udcff"}, {}):
        scene = dict(pile)
        scene.update({} if given else {"name": "\ud800"})
        with pytest.raises(marbles.SceneError, match="name: not UTF-8 text"):
            marbles.Simulation.from_dict(scene, backend="cpu", **given)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(marbles.SceneError, match=r"study: out: an empty path"):
        marbles.study(SCENES / "validation" / "bouncing_ball.yaml", vary={"time.dt": [2e-3]}, out="")
    assert not (tmp_path / "out").exists()  # it wrote into out/study/<scene>
