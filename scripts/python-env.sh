# scripts/python-env.sh — sourced: python_env DIR PACKAGE... makes (once) a
# virtual environment in DIR, beside the system's site-packages, in which
# every PACKAGE imports; wheels in .deps/wheels are used first (a machine
# with no registry: scripts/gpu-check). DIR may be an existing virtual
# environment: the missing packages go into it. Returns non-zero when it cannot.
python_env() {
  local dir=$1 root missing=() p
  shift
  root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
  if [ ! -x "$dir/bin/python" ]; then
    python3 -m venv --system-site-packages "$dir" >/dev/null 2>&1 || { rm -rf "$dir"; return 1; }
  fi
  for p in "$@"; do
    "$dir/bin/python" -c "import $p" >/dev/null 2>&1 || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "setup: installing ${missing[*]} into $dir (PyPI)"
  local pip=("$dir/bin/python" -m pip install -q --disable-pip-version-check)
  if [ -d "$root/.deps/wheels" ]; then
    "${pip[@]}" --no-index --find-links "$root/.deps/wheels" "${missing[@]}" >/dev/null 2>&1 && return 0
    pip+=(--find-links "$root/.deps/wheels")
  fi
  "${pip[@]}" "${missing[@]}"
}
