"""The exceptions of marbles (raised by the extension; importable without it)."""


class SceneError(ValueError):
    """A scene, an argument or an input file is wrong.

    ``file``, ``line`` and ``column`` say where (``line`` is 0 for a scene
    given as a dict: then ``key`` alone names the place), ``key`` is the
    dotted key path (``materials.glass.restitution``) and ``message`` what is
    wrong; ``str(error)`` reads as on the command line:
    ``scenes/x.yaml:12:5: materials.glass.restitution: must be within [0, 1], got 1.3``.
    """

    def __init__(self, text, file="", line=0, column=0, key="", message=""):
        super().__init__(text)
        self.file = file
        self.line = line
        self.column = column
        self.key = key
        self.message = message or text


class RuntimeFailure(RuntimeError):
    """Something failed while running: I/O, the device, the watchdog giving up."""
