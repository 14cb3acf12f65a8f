//! Runs the Python interoperability tests against independent implementations:
//! C3D files with `ezc3d` (tests/c3d_interop.py), the ROS 2 interface
//! definitions with `rosbags` (tests/msg_defs.py), and the shipped body motions
//! against the frames Blender evaluated and the turn's closed form
//! (tests/anny_motion.py), and the linear systems `drape --write-system`
//! writes, read and solved by SciPy (tests/system_file.py). Their Python
//! packages come from tests/requirements.txt, which .ci/run installs; without
//! them these tests fail and say what to install (they never pass silently).

mod support;

fn pytest(file: &str, modules: &str, expect: &str) {
    support::pytest(file, modules, false, &[], expect);
}

#[test]
fn c3d_files_round_trip_with_ezc3d() {
    pytest("tests/c3d_interop.py", "ezc3d, numpy, pytest", "3 passed");
}

#[test]
fn ros2_interface_definitions_parse_with_rosbags() {
    pytest("tests/msg_defs.py", "rosbags, numpy, pytest", "2 passed");
}

#[test]
fn the_shipped_body_motion_skins_as_blender_does() {
    pytest("tests/anny_motion.py", "numpy, pytest", "4 passed");
}

#[test]
fn written_linear_systems_read_and_solve_in_scipy() {
    let dir = support::Scratch::new("system_file");
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    support::pytest(
        "tests/system_file.py",
        "numpy, scipy, pytest",
        false,
        &[
            ("GARMENT_SIM_BIN", &bin),
            ("GARMENT_SIM_TMP", dir.as_os_str()),
        ],
        "3 passed",
    );
}
