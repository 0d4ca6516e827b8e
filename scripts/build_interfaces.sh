#!/usr/bin/env bash
# Generate the ROS 2 interface packages the PyPI wheels lack (tf2_msgs) into the venv, with the
# rosidl generators from the wheels. Idempotent: does nothing when the install is up to date.
#   usage: scripts/build_interfaces.sh [VENV]
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
venv="$(cd "${1:-$here/.venv}" && pwd)"
py="$venv/bin/python"
src="$here/mrslam_ros/interfaces/tf2_msgs"
build="$here/build/interfaces/tf2_msgs"
stamp="$venv/.tf2_msgs.stamp"
if [ -f "$stamp" ] && [ "$stamp" -nt "$src/msg/TFMessage.msg" ] && [ "$stamp" -nt "$src/CMakeLists.txt" ]; then
  exit 0
fi
# The wheels' exported CMake targets name include folders of the machine that built them; point
# them at this venv's Python and numpy headers.
mkdir -p "$(dirname "$build")"
pyinc="$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
npinc="$("$py" -c 'import numpy; print(numpy.get_include())')"
grep -rl --include='*.cmake' -e '/opt/python/cp311-cp311' "$venv/share" "$venv/lib" 2>/dev/null | while read -r f; do
  sed -i -e "s#/opt/python/cp311-cp311/include/python3.11#$pyinc#g" \
         -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$npinc#g" \
         -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/core/include#$npinc#g" "$f"
done
export CMAKE_PREFIX_PATH="$venv" AMENT_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
ld="$("$py" -c 'import os; print(os.environ.get("LD_LIBRARY_PATH", ""))')"
export LD_LIBRARY_PATH="$ld"
cmake -S "$src" -B "$build" -DCMAKE_INSTALL_PREFIX="$venv" -DBUILD_TESTING=OFF \
  -DPython3_EXECUTABLE="$py" -DPYTHON_EXECUTABLE="$py" -DCMAKE_BUILD_TYPE=Release > "$build.log" 2>&1 \
  || { cat "$build.log"; exit 1; }
cmake --build "$build" -j2 >> "$build.log" 2>&1 || { tail -50 "$build.log"; exit 1; }
cmake --install "$build" >> "$build.log" 2>&1 || { tail -20 "$build.log"; exit 1; }
# make the generated Python package importable from the venv
site="$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
gen="$(find "$venv/lib" -path '*site-packages/tf2_msgs' -type d | head -1)"
if [ -n "$gen" ] && [ "$(dirname "$gen")" != "$site" ]; then
  echo "$(dirname "$gen")" > "$site/mrslam_interfaces.pth"
fi
touch "$stamp"
echo "tf2_msgs built into $venv"
