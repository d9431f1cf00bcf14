# scripts/setup.sh — sourced by scripts/run and scripts/test: installs the
# Debian packages that are missing, then configures and builds (Release).
# Environment: BUILD_DIR (default build), MARBLES_CMAKE_ARGS (extra -D flags).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
JOBS=$(nproc 2>/dev/null || echo 2)

# Needed to build the core at all (zlib: compressed VTK frames, written by marbles itself).
REQUIRED_PKGS=(cmake g++ make pkg-config libyaml-cpp-dev libgtest-dev libcli11-dev zlib1g-dev nlohmann-json3-dev)
# Found -> on: OSMesa rendering, PNG, movies, study plots, the scene fuzzer (clang, libFuzzer), and
# python3 for the tests' independent reader of the frames. VTK itself is not installed (docs/vtk-output.md):
# where libvtk9-dev is already present its reader checks the frames too.
# python3-dev and python3-venv: the Python module (below).
OPTIONAL_PKGS=(libosmesa6-dev libpng-dev ffmpeg gnuplot-nox clang libclang-rt-dev python3 python3-dev python3-venv)

missing_packages() {
  local p
  for p in "$@"; do
    dpkg -s "$p" >/dev/null 2>&1 || echo "$p"
  done
}

install_packages() {
  local pkgs=("$@") sudo=""
  [ ${#pkgs[@]} -eq 0 ] && return 0
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 && sudo="sudo" || return 1
  fi
  echo "setup: installing ${pkgs[*]}"
  $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${pkgs[@]}"
}

if command -v dpkg >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
  mapfile -t need < <(missing_packages "${REQUIRED_PKGS[@]}")
  mapfile -t want < <(missing_packages "${OPTIONAL_PKGS[@]}")
  if ! install_packages "${need[@]}" "${want[@]}"; then
    # Offline or unprivileged: the required set must install, the rest is optional.
    install_packages "${need[@]}" || { echo "setup: cannot install ${need[*]}" >&2; exit 1; }
    echo "setup: warning: optional packages not installed: ${want[*]} (no rendering / movies / plots)" >&2
  fi
fi

# The Python module (docs/python.md) builds with nanobind and is tested with
# pytest, from PyPI: a virtual environment in the build folder holds them
# (with NumPy, and SciPy and Matplotlib for the examples), made once. Offline,
# the module is not built. MARBLES_PYTHON=OFF skips it.
python_args=()
if [ "${MARBLES_PYTHON:-AUTO}" != OFF ] && command -v python3 >/dev/null 2>&1; then
  . "$ROOT/scripts/python-env.sh"
  if python_env "$BUILD_DIR/python-env" nanobind numpy pytest scipy matplotlib; then
    python_args=(-DPython_EXECUTABLE="$BUILD_DIR/python-env/bin/python")
  else
    echo "setup: warning: no Python environment (PyPI unreachable?): the Python module is not built" >&2
  fi
fi

echo "setup: configuring $BUILD_DIR (Release)"
mkdir -p "$BUILD_DIR"
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release "${python_args[@]}" ${MARBLES_CMAKE_ARGS:-} >"$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log" >&2; exit 1; }
grep -E "^-- marbles:" "$BUILD_DIR.configure.log" || true
# scripts/run builds only the program (MARBLES_BUILD_TARGETS=marbles); scripts/test builds everything.
if [ -n "${MARBLES_BUILD_TARGETS:-}" ]; then
  echo "setup: building ${MARBLES_BUILD_TARGETS} with $JOBS jobs"
  cmake --build "$BUILD_DIR" -j "$JOBS" --target ${MARBLES_BUILD_TARGETS}
else
  echo "setup: building with $JOBS jobs"
  cmake --build "$BUILD_DIR" -j "$JOBS"
fi
