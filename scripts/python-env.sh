# scripts/python-env.sh — sourced: python_env DIR PACKAGE... makes (once) a
# virtual environment in DIR, beside the system's site-packages, in which
# every PACKAGE imports; wheels in .deps/wheels are used first (a machine
# with no registry: scripts/gpu-check). Returns non-zero when it cannot.
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
  local links=()
  [ -d "$root/.deps/wheels" ] && links=(--find-links "$root/.deps/wheels")
  "$dir/bin/python" -m pip install -q --disable-pip-version-check "${links[@]}" "${missing[@]}" >/dev/null 2>&1 ||
    "$dir/bin/python" -m pip install -q --disable-pip-version-check --no-index "${links[@]}" "${missing[@]}"
}
