#!/usr/bin/env bash
# tests/viewer/viewer_test.sh MARBLES SOURCE_DIR WORK_DIR — the `viewer` test:
# a short run opened in Debian's ParaView (pvpython under xvfb-run), which
# it installs when missing (as root, with apt). Exit 77 (skipped) where
# ParaView cannot be had.
set -euo pipefail
marbles=$1 src=$2 work=$3
need=()
command -v pvpython >/dev/null 2>&1 || need+=(paraview python3-paraview)
command -v xvfb-run >/dev/null 2>&1 || need+=(xvfb xauth)
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "viewer test: installing ${need[*]}"
    if ! (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
          "${need[@]}") >"$work.apt.log" 2>&1; then
      echo "skipped: cannot install ${need[*]} (see $work.apt.log)"
      exit 77
    fi
  else
    echo "skipped: pvpython or xvfb-run is missing and cannot be installed here (not root or no apt-get)"
    exit 77
  fi
fi
rm -rf "$work"
mkdir -p "$work"
cat >"$work/scene.yaml" <<'YAML'
format: 1
name: viewer
time: {duration: 0.3, dt: 1.0e-3, substeps: 2}
effects: [gravity, collisions, walls, restitution, friction]
materials:
  glass: {density: 2500, restitution: 0.5, friction: 0.4}
  steel: {density: 7800, restitution: 0.5, friction: 0.4}
walls:
  - box: {min: [0, 0, 0], max: [0.2, 0.2, 0.4]}
  - plane: {point: [0, 0, 0.02], normal: [0, 0, 1]}
    velocity: [0, 0, 0.05]
particles:
  - random: {count: 150, min: [0.02, 0.02, 0.05], max: [0.18, 0.18, 0.2], radius: 0.008, seed: 1}
  - random: {count: 50, min: [0.02, 0.02, 0.22], max: [0.18, 0.18, 0.38], radius: 0.006, seed: 2}
    material: steel
output:
  vtk: {every: 30}
  contacts: {every: 30}
  fields: [radius, velocity, angular_velocity, id, material, speed, contacts]
YAML
"$marbles" run "$work/scene.yaml" --quiet --backend cpu --out "$work/out"
# A loaded machine now and then starts ParaView before its X server takes
# connections ("bad X server connection"): that, and only that, is tried
# again, up to three times; any other failure is the test's.
for try in 1 2 3; do
  status=0
  xvfb-run -a -s "-screen 0 1280x1024x24" pvpython "$src/tests/viewer/check_output.py" "$work/out" \
    "$src/scripts/paraview-view.py" glass,steel >"$work/check.log" 2>&1 || status=$?
  cat "$work/check.log"
  [ $status -eq 0 ] && exit 0
  grep -q "bad X server connection" "$work/check.log" || exit $status
  echo "viewer test: the X server was not ready (try $try of 3)"
done
exit $status
