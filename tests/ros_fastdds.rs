//! The node against ROS 2's default middleware: rclpy on eProsima Fast DDS
//! (rmw_fastrtps_cpp, ROS 2 Jazzy from PyPI, tests/ros_fastdds.py) in the
//! venv `bash tests/ros2_venv.sh` makes (target/ros-venv, with
//! garment_sim_msgs built for Python): graph, topics and types, cloud and mesh
//! contents, /clock, the node's services, the parameter services, obstacles
//! and pins, a garment trial as the scene, the garment's weight on
//! `body/wrench`. Everything runs in a network namespace made for the test
//! (`unshare -rn`: only a loopback interface), so no packet leaves it.

mod support;

#[test]
fn node_interoperates_with_rclpy_on_fast_dds() {
    let venv = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ros-venv");
    let python = venv.join("bin/python");
    let python = python.to_str().expect("a UTF-8 path");
    support::require_python_in(
        python,
        "rclpy, garment_sim_msgs.msg, numpy, pytest",
        "bash tests/ros2_venv.sh",
    );
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    let rmw = std::ffi::OsString::from("rmw_fastrtps_cpp");
    support::pytest_in(
        python,
        "tests/ros_fastdds.py",
        true,
        &[("GARMENT_SIM_BIN", &bin), ("RMW_IMPLEMENTATION", &rmw)],
        "6 passed",
    );
}
