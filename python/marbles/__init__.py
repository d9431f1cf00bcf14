"""marbles from Python: build scenes, step, and read and change the state as arrays.

    import marbles
    sim = marbles.Simulation("scenes/demo.yaml", backend="auto", set={"time.dt": 5e-4})
    sim.step(100)
    z = sim.positions[:, 2]          # a NumPy view of the step's own array (CPU backend)

The scene format, its checks and its error messages are those of ``marbles run``
(docs/scene-format.md); docs/python.md describes this module.
"""

import atexit
import inspect
import json
import math
import numbers
import os
import warnings

import numpy as np

from .errors import RuntimeFailure, SceneError
from . import _marbles

__all__ = ["Simulation", "DeviceArray", "SceneError", "RuntimeFailure", "pairs", "study", "cuda_device",
           "__version__"]

__version__ = _marbles.version


# --- scenes and overrides ------------------------------------------------------

def _whole(value, what, least):
    """A count: an int (or NumPy integer), or a float without a fraction
    (``1e3``); a bool, a string or 2.5 is refused rather than rounded."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{what}: a whole number, got {value!r}")
    if not isinstance(value, numbers.Integral):
        if not float(value).is_integer():
            raise ValueError(f"{what}: a whole number, got {value!r}")
        value = float(value)
    value = int(value)
    if value < least:
        raise ValueError(f"{what} must be >= {least}, got {value}")
    return value


def _utf8_text(text, key, where):
    """``text``, where it is UTF-8 text; a lone surrogate ("\\ud800"), which no
    scene text or folder's name holds, raises SceneError naming ``where``."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError(f"{where}: not UTF-8 text: {text!r}", key=key, message=f"not UTF-8 text: {text!r}") \
            from None
    return text


def _flow_text(text):
    """A string inside a list or a map (a key, or a value there) as YAML
    text: plain where it is a plain word that reads as itself, else
    double-quoted, since a comma, bracket or brace there would split or end it
    (``{"steel,glass": ...}`` made two materials, ``"'glass'"`` lost its
    quotes, ``"null"`` read as nothing)."""
    if text and all(c.isalnum() or c in "_.-+/" for c in text) and _marbles.reads_as_itself(text):
        return text
    return json.dumps(text, ensure_ascii=False)


def _yaml_text(value, key, strings="values", nested=False):
    """A value as the YAML text of a ``--set key=value`` override. A string is
    that string (``strings="values"``: double-quoted where the scene's reader
    would not read it plainly as itself, so ``--set`` of the same plain text
    gives the same override), or YAML text as given (``strings="text"``: a
    study's values, ``"[0, 0, -9.81]"``)."""
    value = _unmasked(value, key)
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return ".nan"
        if math.isinf(v):
            return ".inf" if v > 0 else "-.inf"
        return repr(v)
    if isinstance(value, str):
        _utf8_text(value, key, f"set: {key}")
        # "run #2" would end at the #, "&a x" be an anchor, "null" nothing.
        # A list's or map's YAML text goes in set=["key=[a, b]"].
        if strings == "text":  # a study's value: YAML text as given, also inside a list
            return value
        if nested:
            return _flow_text(value)
        if _marbles.reads_as_itself(value):
            return value
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, np.ndarray) and value.ndim == 0:  # np.array(1e-3): its one value
        return _yaml_text(value.item(), key, strings, nested)
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_yaml_text(v, key, strings, True) for v in value) + "]"
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise SceneError(f"set: {key}: keys are strings, got {k!r}", key=key,
                                 message=f"keys are strings, got {k!r}")
        return "{" + ", ".join(f"{_flow_text(k)}: {_yaml_text(v, key, strings, True)}" for k, v in value.items()) + "}"
    raise SceneError(f"set: {key}: cannot be written as a scene value: {value!r}", key=key,
                     message=f"cannot be written as a scene value: {value!r}")


def _overrides(set):
    """``{"time.dt": 5e-4}`` (or ``["time.dt=5e-4"]``) as the command line's ``--set`` texts."""
    if set is None:
        return []
    if isinstance(set, dict):
        texts = []
        for key, value in set.items():
            try:
                texts.append(f"{key}={_yaml_text(value, key)}")
            except RecursionError:  # a list that holds itself, or nests past Python's depth
                raise SceneError(f"set: {key}: the value holds itself, or nests deeper than any scene value does",
                                 key=key, message="the value holds itself, or nests deeper than any scene value "
                                 "does") from None
    elif isinstance(set, (bytes, bytearray, memoryview)):  # iterated, they would be numbers
        raise TypeError(f"set: a dict of key -> value, or a list of 'key=value' texts (str), got {type(set).__name__}")
    elif isinstance(set, str):
        texts = [set]
    elif not hasattr(set, "__iter__"):
        raise TypeError(f"set: a dict of key -> value, or a list of 'key=value' texts, got {set!r}")
    else:
        texts = [str(item) for item in set]
    for text in texts:  # in a key or a text
        _utf8_text(text, "set", "set")
    return texts


def _plain(value, key):
    """A scene dict as JSON-ready data: NumPy arrays and scalars as lists and
    numbers; non-finite numbers, and integers past any double, as YAML's
    .nan/.inf, which the checks refuse with the key's name."""
    value = _unmasked(value, key)
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise SceneError(f"<dict>: {key}: keys are strings, got {k!r}", file="<dict>", key=key,
                                 message=f"keys are strings, got {k!r}")
            out[k] = _plain(v, f"{key}.{k}" if key else k)
        return out
    if isinstance(value, np.ndarray) and value.ndim == 0:  # np.array(0.05): its one value
        return _plain(value.item(), key)
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v, f"{key}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        v = int(value)
        try:
            float(v)
        except OverflowError:  # past any double (10**400): infinite, as such a number in a scene file is
            return ".inf" if v > 0 else "-.inf"
        return v
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isfinite(v):
            return v
        return ".nan" if math.isnan(v) else (".inf" if v > 0 else "-.inf")
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise SceneError(f"<dict>: {key}: not a scene value: {value!r}", file="<dict>", key=key,
                     message=f"not a scene value: {value!r}")


def _json_text(text):
    """Whether a record's scene dict, where it has one, is JSON text."""
    if text is None:
        return True
    try:
        json.loads(text)
    except (ValueError, RecursionError):
        return False
    return True


def _implementation(precision):
    return _marbles.SimulationDouble if precision == "double" else _marbles.SimulationFloat


def _check_called_with_one(function, what):
    """Refuses, before any step, a function that cannot be called with one
    argument (the simulation). One whose signature Python cannot read (some
    built-ins) is left to its call."""
    try:
        signature = inspect.signature(function, follow_wrapped=False)  # a wrapper is called as it is
    except (TypeError, ValueError):
        return
    try:
        signature.bind(None)
    except TypeError as e:
        raise TypeError(f"{what}: is called with one argument, the simulation; {function!r} "
                        f"takes {signature} ({e})") from None


def _is_false(value):
    """False, or NumPy's False (a callback's ``x > limit`` on arrays gives one)."""
    return value is False or (isinstance(value, np.bool_) and not value)


def _path(value, what):
    """A path argument as the text the program takes: a str, bytes or
    os.PathLike; refused by its name where it is none, or holds bytes that
    are not UTF-8 (the program's paths are UTF-8 text)."""
    try:
        value = os.fspath(value)
    except TypeError:
        raise TypeError(f"{what}: a path (str, bytes or os.PathLike), got {value!r}") from None
    if isinstance(value, bytes):
        value = os.fsdecode(value)
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError(f"{what}: a path of UTF-8 text, got {value!r} (rename the file or folder)") from None
    if "\0" in value:  # the program would read the path only up to it: another file
        raise ValueError(f"{what}: a path holds no NUL byte, got {value!r}")
    return value


def _choice(value, what, choices):
    """A string argument among ``choices`` (the program says which, by name, for other strings)."""
    if not isinstance(value, str):
        raise TypeError(f"{what}: one of {', '.join(choices)}, got {value!r}")
    return value


_BACKENDS = ("auto", "cpu", "cuda")


@atexit.register
def _at_exit():
    # A step still running in a daemon thread waits out the interpreter's
    # end instead of being stopped where it cannot be (python/gil.hpp).
    _marbles.at_exit()


def _steps_in(time, dt):
    """The steps of dt in a time, rounded half away from zero, as the
    program rounds a duration (std::llround): 2.5 steps are 3."""
    steps = time / dt
    whole = math.floor(steps)
    return int(whole) + (1 if steps - whole >= 0.5 else 0)


def _on_host(values):
    """A device array's host copy (CuPy's get(), a marbles.DeviceArray's
    numpy(), PyTorch's cpu()); anything else as it is."""
    if not hasattr(values, "__cuda_array_interface__"):
        return values
    if hasattr(values, "get"):
        return values.get()
    if isinstance(values, DeviceArray):
        return values.numpy()
    return values.cpu().numpy() if hasattr(values, "cpu") else values


def _unmasked(values, what):
    """A masked array's data, where no entry is masked; one with masked
    entries (or NumPy's masked constant, an entry taken from one) is refused:
    their hidden values would be read as numbers. Anything else as it is."""
    if not np.ma.isMaskedArray(values):
        return values
    masked = np.flatnonzero(np.ma.getmaskarray(values))
    if masked.size:
        raise ValueError(f"{what}: a masked array with {masked.size} masked entr"
                         f"{'y' if masked.size == 1 else 'ies'} (the first at flat index {masked[0]}); "
                         "fill them first (.filled(value))")
    return np.ma.getdata(values)


def _real_array(values, what):
    """``values`` as a NumPy array of numbers (bool, text, dates and ragged
    lists refused by name, where NumPy's own errors named nothing; a masked
    array's hidden entries refused, where they were read as numbers)."""
    values = _unmasked(values, what)
    try:
        array = np.asarray(values)
    except (TypeError, ValueError) as e:  # a ragged list
        raise TypeError(f"{what}: an array of numbers, got {type(values).__name__} ({e})") from None
    if array.dtype.kind not in "iufc":  # bool, text, objects, dates: no coordinates or speeds
        raise TypeError(f"{what}: an array of numbers, got {array.dtype} ({type(values).__name__})")
    return array


def _threads(value):
    """``threads``: 0 (OMP_NUM_THREADS, else every core) or 1 to 4096, as ``--threads``."""
    value = _whole(value, "threads", 0)
    if value > 4096:
        raise ValueError(f"threads must be <= 4096, got {value}")
    return value


# --- device arrays -------------------------------------------------------------

class DeviceArray:
    """A sphere array of the CUDA backend, in device memory, without a copy.

    ``cupy.asarray(a)`` (``__cuda_array_interface__``) and
    ``torch.from_dlpack(a)`` (DLPack) see the step's own memory; ``a.numpy()``
    is a host copy. Writes through the device memory are taken, and checked,
    at the next step, like writes through the NumPy views of the CPU backend.
    """

    def __init__(self, simulation, what, array, address, shape, dtype, readonly):
        self._simulation = simulation  # keeps the device memory alive
        self._what = what
        self._array = array
        self._address = address
        self.shape = shape
        self.dtype = np.dtype(dtype)
        self.readonly = readonly

    @property
    def __cuda_array_interface__(self):
        return {"shape": self.shape, "typestr": self.dtype.str, "data": (self._address, self.readonly),
                "strides": None, "version": 3}

    def __dlpack__(self, **kwargs):
        return self._array.__dlpack__(**kwargs)

    def __dlpack_device__(self):
        return self._array.__dlpack_device__()

    def __len__(self):
        return self.shape[0]

    def numpy(self):
        """A host copy (NumPy)."""
        return self._simulation._impl.copy(self._what)

    def __repr__(self):
        return f"DeviceArray({self._what}, shape={self.shape}, dtype={self.dtype}, device=cuda)"


# --- the simulation ------------------------------------------------------------

class Simulation:
    """A scene, stepped: ``marbles run`` without the files.

    ``Simulation("scene.yaml", backend="auto", set={"time.dt": 5e-4}, threads=0)``
    loads and checks the scene as ``marbles run`` does (``set`` are its
    ``--set`` overrides; ``threads`` its ``--threads``); the same scene stepped
    here and by ``marbles run`` gives the same bits. The precision is the
    scene's ``solver.precision``.
    """

    def __init__(self, scene, backend="auto", set=None, threads=0):
        source = Simulation._file_source(scene, set)
        self._build(source, Simulation._precision(source), backend, threads)

    @staticmethod
    def _file_source(scene, set):
        """A scene file's record: its path and overrides."""
        path = _path(scene, "scene")
        if not path:
            raise SceneError("scene: a scene file is needed, got an empty path", key="scene",
                             message="a scene file is needed, got an empty path")
        return {"scene": path, "set": _overrides(set)}

    @staticmethod
    def _precision(source):
        """A record's solver.precision, its overrides applied as the loader applies them."""
        if "dict" in source:
            return _marbles.scene_precision_json(source["dict"], source["set"])
        return _marbles.scene_precision(source["scene"], source["set"])

    @classmethod
    def from_dict(cls, scene, backend="auto", set=None, threads=0, name=None):
        """A scene given as a dict with the keys of a scene file. Errors name
        the key path (``SceneError.key``; ``line`` is 0). ``name`` (or the
        scene's ``name``) names the default output folder, ``out/<name>``."""
        source = cls._dict_source(scene, set, name)
        self = cls.__new__(cls)
        self._build(source, cls._precision(source), backend, threads)
        return self

    @staticmethod
    def _stem(name, scene):
        """The default output folder's name: ``name``, else the scene dict's, else "scene"."""
        if name is not None and not isinstance(name, str):
            raise TypeError(f"name: the output folder's name, a string, got {name!r}")
        named = scene.get("name") if isinstance(scene, dict) else None
        return _utf8_text(name or (named if isinstance(named, str) else None) or "scene", "name", "name")

    @staticmethod
    def _dict_source(scene, set, name):
        """A scene dict's record: its JSON text, name and overrides."""
        if not isinstance(scene, dict):
            raise SceneError(f"<dict>: a scene is a dict of keys (time, materials, particles, ...), got "
                             f"{type(scene).__name__}", file="<dict>",
                             message="a scene is a dict of keys (time, materials, particles, ...)")
        try:
            text = json.dumps(_plain(scene, ""))
        except RecursionError:  # a dict that holds itself, or nests past Python's depth
            raise SceneError("<dict>: the scene holds itself, or nests deeper than any scene does", file="<dict>",
                             message="the scene holds itself, or nests deeper than any scene does") from None
        return {"dict": text, "name": Simulation._stem(name, scene), "set": _overrides(set)}

    @classmethod
    def restart(cls, path, scene=None, backend="auto", set=None, threads=0):
        """Resumes from a checkpoint (``sim.checkpoint(path)``, or one of
        ``marbles run``'s). Without ``scene``, the scene and overrides are
        those recorded beside a checkpoint written from Python
        (``path + ".scene.json"``); a checkpoint of ``marbles run`` needs
        ``scene`` (and the run's ``set``)."""
        path = _path(path, "restart: path")
        label = "<dict>"  # a scene dict's name in errors
        if scene is None:
            try:
                with open(path + ".scene.json", encoding="utf-8") as f:
                    source = json.load(f)
            except FileNotFoundError:
                raise SceneError(f"{path}: restart: no {os.path.basename(path)}.scene.json beside the checkpoint "
                                 "says which scene it belongs to; give scene=", file=path, key="restart",
                                 message="give scene=") from None
            except OSError as e:  # a folder, unreadable
                raise RuntimeFailure(f"cannot read {path}.scene.json: {e.strerror or e}") from None
            except RecursionError:  # JSON nested past Python's depth: no record is
                raise SceneError(f"{path}.scene.json: restart: not the record of a scene (nested past any "
                                 "scene's depth); give scene=", file=path + ".scene.json", key="restart",
                                 message="give scene=") from None
            except ValueError as e:  # not JSON
                raise SceneError(f"{path}.scene.json: restart: not the record of a scene ({e}); give scene=",
                                 file=path + ".scene.json", key="restart", message="give scene=") from None
            if (not isinstance(source, dict) or not isinstance(source.get("set"), list)
                    or not all(isinstance(o, str) for o in source["set"])
                    or not isinstance(source.get("scene", ""), str)
                    or not isinstance(source.get("name", ""), (str, type(None)))
                    or not (isinstance(source.get("dict"), str) or isinstance(source.get("scene"), str))
                    or not _json_text(source.get("dict"))):
                raise SceneError(f"{path}.scene.json: restart: not the record of a scene; give scene=",
                                 file=path + ".scene.json", key="restart", message="give scene=")
            overrides = source["set"] if set is None else _overrides(set)
            if source.get("dict") is not None:
                # The recorded text as it was (its fingerprint is the checkpoint's).
                text = source["dict"]
                source = {"dict": text, "name": cls._stem(source.get("name"), json.loads(text)), "set": overrides}
                label = path + ".scene.json"
            else:
                source = cls._file_source(source["scene"], overrides)
        elif isinstance(scene, dict):
            source = cls._dict_source(scene, set, None)
        else:
            source = cls._file_source(scene, set)
        # The checkpoint's precision wins, as with marbles run --restart: the
        # same scene and overrides in it, no override added (the checkpoint
        # holds the fingerprint of the scene and its overrides, which one more
        # would change; marbles run --precision adds none). The scene is built
        # once, in it; without a checkpoint there, in its own (the restart
        # then says what is missing).
        precision = _marbles.checkpoint_precision(path) if os.path.exists(path) else cls._precision(source)
        self = cls.__new__(cls)
        self._build(source, precision, backend, threads, label)
        self._impl.restart(path)
        return self

    def _build(self, source, precision, backend, threads, label="<dict>"):
        """The simulation of a scene's record in a precision; its warnings said once. ``label``
        names a scene dict in errors: "<dict>", or the record file it was read from."""
        backend = _choice(backend, "backend", _BACKENDS)
        overrides = source["set"]
        if "dict" in source:
            impl = _implementation(precision)(source["dict"], label, source["name"], overrides, backend,
                                              _threads(threads))
        else:
            impl = _implementation(precision)(source["scene"], "", "", overrides, backend, _threads(threads))
        self._impl = impl
        self._source = dict(source, scene=os.path.abspath(source["scene"])) if "scene" in source else source
        for text in impl.warnings:
            warnings.warn(text, stacklevel=3)  # at the caller of __init__, from_dict or restart

    # --- stepping ---
    def _check_substeps(self, steps, what):
        # A run's substeps limit, the one `marbles run` holds a run to (README "Limits").
        limit = _marbles.substeps_limit()
        if steps * self.substeps > limit:
            count = f"{steps}" if steps < 10**15 else f"{steps:.3e}"
            raise ValueError(f"{what}: {count} steps make {steps * self.substeps:.3g} substeps, more than the "
                             f"limit {limit:.0e} a call")

    def step(self, n=1):
        """Advances n steps of dt. Arrays handed out are checked first (a
        non-finite value raises ValueError and nothing moves)."""
        n = _whole(n, "step: n", 0)
        self._check_substeps(n, "step: n")
        self._impl.step(n)
        return self

    def run(self, until=None, callback=None, every=1):
        """Steps until the time ``until`` (default: the scene's duration),
        calling ``callback(sim)`` every ``every`` steps; a callback that
        returns False stops the run."""
        every = _whole(every, "run: every", 1)
        if callback is not None and not callable(callback):
            raise TypeError(f"run: callback: a function of the simulation, got {callback!r}")
        if callback is not None:
            _check_called_with_one(callback, "run: callback")
        if until is not None and (isinstance(until, (bool, np.bool_)) or not isinstance(until, numbers.Real)):
            raise TypeError(f"run: until: a time in seconds, got {until!r}")
        try:
            float(until if until is not None else 0)
        except OverflowError:  # an int past any float
            raise ValueError(f"run: until is too large a time, got a number of {len(str(abs(int(until))))} digits") \
                from None
        if until is not None and not (math.isfinite(until) and until >= 0):
            raise ValueError(f"run: until must be a finite time >= 0, got {until!r}")
        if until is not None and not math.isfinite(float(until) / self.dt):
            raise ValueError(f"run: until is too large a time, got {float(until):g}")
        target = self._impl.total_steps if until is None else _steps_in(float(until), self.dt)
        if until is not None and target < self.steps:
            raise ValueError(f"run: until = {float(until):g} s is before the simulation's time, {self.time:g} s")
        self._check_substeps(target - self.steps, "run: until")
        while self.steps < target:
            self._impl.step(min(every, target - self.steps))
            if callback is not None and _is_false(callback(self)):
                break
        return self

    # --- what the run is ---
    time = property(lambda self: self._impl.time, doc="simulated time, s")
    steps = property(lambda self: self._impl.steps, doc="steps taken")
    dt = property(lambda self: self._impl.dt, doc="the step, s")
    substeps = property(lambda self: self._impl.substeps, doc="substeps per step")
    duration = property(lambda self: self._impl.duration, doc="the scene's time.duration, s")
    pipeline = property(lambda self: self._impl.pipeline, doc="the stages the step runs, one per line")
    backend = property(lambda self: self._impl.backend, doc="'cpu' or 'cuda'")
    precision = property(lambda self: self._impl.precision, doc="'float' or 'double'")
    name = property(lambda self: self._impl.name, doc="the scene's name")
    material_names = property(lambda self: self._impl.materials, doc="material names, by material id")
    max_overlap = property(lambda self: self._impl.max_overlap,
                           doc="the last step's deepest overlap, of the smaller radius (before the first step, "
                               "the state's at the start or restart)")
    rollbacks = property(lambda self: self._impl.rollbacks, doc="steps the watchdog redid")
    unswept_steps = property(lambda self: self._impl.unswept_steps,
                             doc="steps the watchdog kept with a sphere still unswept at its finest substep")

    def __len__(self):
        return self._impl.size

    def __copy__(self):
        raise TypeError("a marbles.Simulation cannot be copied (a copy would share its state); checkpoint() "
                        "writes the state, Simulation.restart() makes another simulation from it")

    def __deepcopy__(self, memo):
        self.__copy__()

    def __reduce__(self):
        raise TypeError("a marbles.Simulation cannot be pickled; checkpoint() writes the state, "
                        "Simulation.restart() makes another simulation from it")

    def __repr__(self):
        return (f"<marbles.Simulation {self.name!r}: {len(self)} spheres, {self.backend}, {self.precision}, "
                f"t = {self.time:g} s, {self.steps} steps>")

    # --- the state ---
    def _array(self, what):
        if self._impl.renumbers:  # solver.renumber: copies in the scene's numbering (docs/python.md)
            array = self._impl.copy(what)
            array.flags.writeable = False
            return array
        if not self._impl.on_device:
            return self._impl.view(what)
        array, address = self._impl.view(what)
        shape = (len(self), 3) if what in ("position", "velocity", "angular_velocity") else (len(self),)
        dtype = np.uint32 if what == "material" else (np.float64 if self.precision == "double" else np.float32)
        return DeviceArray(self, what, array, address, shape, dtype, what in ("radius", "material"))

    positions = property(lambda self: self._array("position"),
                         lambda self, values: self._assign("position", values),
                         doc="(N, 3) centres, m: writable in place (read-only copies where the "
                             "scene has solver.renumber); assigning copies")
    velocities = property(lambda self: self._array("velocity"),
                          lambda self, values: self._assign("velocity", values), doc="(N, 3) m/s")
    angular_velocities = property(lambda self: self._array("angular_velocity"),
                                  lambda self, values: self._assign("angular_velocity", values),
                                  doc="(N, 3) rad/s")
    radii = property(lambda self: self._array("radius"), doc="(N,) m, read-only")
    materials = property(lambda self: self._array("material"), doc="(N,) material ids, read-only")

    @property
    def ids(self):
        """(N,) sphere ids (the order of the scene's particle blocks), read-only."""
        ids = np.arange(len(self), dtype=np.uint32)
        ids.flags.writeable = False
        return ids

    def _assign(self, what, values):
        dtype = np.float64 if self.precision == "double" else np.float32
        values = _on_host(values)
        plural = {"velocity": "velocities", "angular_velocity": "angular_velocities"}.get(what, what + "s")
        array = _real_array(values, plural)
        if np.iscomplexobj(array):  # the imaginary part would be dropped without a word
            raise TypeError(f"{what}: real numbers, got a complex array")
        if array.shape != (len(self), 3):  # before the copy, which makes a 0-d array (1,)
            raise ValueError(f"{plural}: expected shape ({len(self)}, 3), got {array.shape}")
        with np.errstate(over="ignore"):  # a value past the precision's range: named below, not warned of
            cast = np.ascontiguousarray(array, dtype=dtype)
        if cast.dtype != array.dtype:  # finite as given, infinite in the precision ("not finite" said 1e39)
            lost = np.flatnonzero(np.isfinite(array).all(axis=1) & ~np.isfinite(cast).all(axis=1))
            if lost.size:
                raise ValueError(f"{plural}[{lost[0]}] is too large for {self.precision} precision; "
                                 "the state is unchanged")
        self._impl.assign(what, cast)

    def contacts(self):
        """The contacts of the last substep that press: a dict of arrays —
        pairs (M, 2) (b is a wall's index where wall is True), wall, normal
        (M, 3, from b to a), normal_force (M,) N, tangential_force (M, 3) N,
        overlap (M,) m, point_a and point_b (M, 3): the line's ends."""
        return self._impl.contacts()

    def kinetic_energy(self):
        """Translational and rotational kinetic energy of the movable spheres, J."""
        return self._impl.kinetic_energy()

    def write_frame(self, dir, overwrite=False):
        """Writes the state as ``dir/frames/frame_NNNNNN.vtp`` and keeps
        ``dir/series.pvd`` (ParaView) up to date; returns the frame's path.
        A folder this simulation has not written to that holds another
        run's output raises ValueError, unless ``overwrite=True``: then that
        run's files (those ``marbles run --overwrite`` replaces) are set
        aside in ``dir/.earlier-run-PID`` and removed when this series ends
        (``end_frames``, or the simulation's end), as the command removes
        them when its run ends; a process that dies first leaves them whole
        there. Until the series ends the folder is its own: another
        simulation's frames, ``marbles run`` and ``marbles render`` there
        are refused."""
        if not isinstance(overwrite, (bool, np.bool_)):  # "False" would be true, and replace a run's files
            raise TypeError(f"write_frame: overwrite is True or False, got {overwrite!r}")
        return self._impl.write_frame(_path(dir, "write_frame: dir"), bool(overwrite))

    def end_frames(self, dir=None):
        """Ends the series of frames written to ``dir`` (every series with
        none): the folder is let go (``marbles render`` may read it, another
        run write there), and the files of an earlier run it replaced are
        removed. A later ``write_frame`` there finds its frames as an
        earlier run's output. A folder with no series is no error."""
        return self._impl.end_frames(None if dir is None else _path(dir, "end_frames: dir"))

    def checkpoint(self, path):
        """Writes a checkpoint (``marbles run --restart`` reads it too) and,
        beside it, ``path + ".scene.json"``: the scene it belongs to."""
        path = _path(path, "checkpoint: path")
        record = path + ".scene.json"
        if path and os.path.exists(record) and not os.path.isfile(record):  # a folder or device: refused up front
            raise RuntimeFailure(f"cannot write {record}: it is not a file; nothing was written")
        scene = self._source.get("scene")
        for target in (path, record):
            if scene and target and os.path.isfile(target) and os.path.isfile(scene) and os.path.samefile(target, scene):
                raise ValueError(f"checkpoint: {target} is this simulation's scene file; choose another path "
                                 "(nothing was written)")
        self._impl.checkpoint(path, json.dumps(self._source))  # both written to a temporary and renamed

    def reference(self):
        """The scene's reference (``reference:``) against the run so far, as a
        dict (kind, expected, measured, error, note), or None. A figure
        the run does not give (a ``finest`` reference's error: the study's
        finest setting gives it) is None, as summary.json writes null."""
        result = self._impl.reference()
        if result is None:
            return None

        def known(value):
            if isinstance(value, float):
                return None if math.isnan(value) else value
            if isinstance(value, list):
                return [known(v) for v in value]
            return value

        return {key: known(value) for key, value in result.items()}

    def summary(self):
        """The run's figures as summary.json has them (means over the steps)."""
        out = {"scene": self._source.get("scene", "<dict>"), "scene_name": self.name, "spheres": len(self),
               "backend": self.backend,
               "precision": self.precision, "steps": self.steps, "substeps": self.substeps, "dt": self.dt,
               "simulated_time": self.time}
        out.update(self._impl.totals())
        out["kinetic_energy_end"] = self.kinetic_energy()
        out.update(self._impl.end_figures())
        return out


# --- the broad phase and the study ---------------------------------------------

def pairs(xyzr, backend="auto", algorithm="home", margin=0.0):
    """The overlapping pairs of an (N, 4) array of x, y, z, r: an (M, 2) uint32
    array of i < j, sorted — what ``marbles pairs`` prints. ``algorithm``:
    home, subdivision (the broad phase of the step) or brute (the oracle);
    ``backend`` auto|cpu|cuda. A float64 array (either byte order) or a wider
    float is searched in double, anything else in float; a device array
    (CuPy, PyTorch) is copied to the host."""
    array = _real_array(_on_host(xyzr), "xyzr")
    if np.iscomplexobj(array):  # the imaginary part would be dropped without a word
        raise TypeError("xyzr: real numbers, got a complex array")
    if isinstance(margin, (bool, np.bool_)) or not isinstance(margin, numbers.Real):
        raise TypeError(f"margin: a distance in m, got {margin!r}")
    try:
        margin = float(margin)
    except OverflowError:  # an int past any float
        raise ValueError(f"margin: too large a distance, got a number of {len(str(abs(int(margin))))} digits") \
            from None
    algorithm = _choice(algorithm, "algorithm", ("home", "subdivision", "brute"))
    backend = _choice(backend, "backend", _BACKENDS)
    if array.ndim != 2 or array.shape[1] != 4:  # before the copy, which makes a 0-d array (1,)
        raise SceneError(f"xyzr: expected an (N, 4) array of x, y, z, r, got shape {array.shape}", key="xyzr",
                         message=f"expected an (N, 4) array of x, y, z, r, got shape {array.shape}")
    # By kind and size: a big-endian float64 (">f8") is no np.float64, and was searched in float.
    double = array.dtype.kind == "f" and array.dtype.itemsize >= 8
    array = np.ascontiguousarray(array, dtype=np.float64 if double else np.float32)
    find = _marbles.pairs_double if double else _marbles.pairs_float
    return find(array, algorithm, backend, margin)


def _program_path():  # not `_program`: importing the submodule of that name would replace it
    """The marbles program that runs each combination of a study."""
    here = os.path.dirname(os.path.abspath(__file__))
    candidates = [os.environ.get("MARBLES_PROGRAM"), os.path.join(here, "bin", "marbles")]
    try:
        from ._program import PROGRAM
        candidates.append(PROGRAM)
    except ImportError:
        pass
    for candidate in candidates:
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    raise RuntimeFailure("the marbles program is not found (set MARBLES_PROGRAM)")


def _study_out(out):
    """A study's folder as the program takes it: "" for the default
    (out/study/<scene>); an empty path given is refused, as ``--out ''`` is,
    where it chose the default without a word."""
    if out is None:
        return ""
    path = _path(out, "study: out")
    if not path:
        raise SceneError("study: out: an empty path (leave it out for out/study/<scene>)", key="out",
                         message="an empty path (leave it out for out/study/<scene>)")
    return path


def study(scene, vary, set=None, backend="auto", repeats=1, out=None, overwrite=False):
    """``marbles study``: the scene at every combination of ``vary``
    (``{"time.dt": [1e-3, 5e-4], "solver.iterations": [5, 10]}``), each run
    ``repeats`` times; returns the table as a list of dicts (the varied keys,
    reference, error, measured, ms_per_step, ms_per_simulated_second, steps,
    pareto) and writes study.md, study.csv (and study.png) under ``out``
    (default out/study/<scene>). A file there that no earlier study wrote
    (one of the tables' names, runs/N) is refused unless ``overwrite``."""
    if not isinstance(overwrite, (bool, np.bool_)):  # "False" would be true, and replace a user's files
        raise TypeError(f"study: overwrite is True or False, got {overwrite!r}")
    if not isinstance(vary, dict) or not vary:
        raise SceneError("vary: give a dict of key -> list of values", key="vary",
                         message="give a dict of key -> list of values")
    repeats = _whole(repeats, "repeats", 1)
    if repeats > 1000:  # as marbles study --repeats
        raise ValueError(f"repeats must be <= 1000, got {repeats}")

    def top_level_comma(text):
        depth = 0
        for c in text:
            depth += c in "[{"
            depth -= c in "]}"
            if c == "," and depth == 0:
                return True
        return False

    texts = []
    for key, values in vary.items():
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            values = [values]
        items = [_yaml_text(v, key, strings="text") for v in values]
        for text in items:
            if top_level_comma(text):  # the study's list is comma-separated
                raise ValueError(f"vary[{key!r}]: a value may not hold a comma outside brackets, got {text!r}")
        texts.append(f"{key}=" + ",".join(items))
    return _marbles.study(_path(scene, "study: scene"), texts, _overrides(set), _choice(backend, "study: backend",
                                                                                       _BACKENDS), repeats,
                          _study_out(out), _program_path(), bool(overwrite))


def cuda_device():
    """(available, name or why not) of the CUDA device marbles would use."""
    return _marbles.cuda_device()
