//! Runs the Python interoperability tests against independent implementations:
//! C3D files with `ezc3d` (tests/c3d_interop.py) and the ROS 2 interface
//! definitions with `rosbags` (tests/msg_defs.py). Their Python packages come
//! from tests/requirements.txt, which .ci/run installs; without them these
//! tests fail and say what to install (they never pass silently).

use std::process::Command;

fn pytest(file: &str, modules: &str, expect: &str) {
    let probe = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .expect("python3 is needed for the interoperability tests");
    assert!(
        probe.status.success(),
        "{file} needs Python packages: python3 -m pip install -r tests/requirements.txt\n{}",
        String::from_utf8_lossy(&probe.stderr)
    );
    let out = Command::new("python3")
        .args(["-m", "pytest", "-q", "-rs", file])
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(out.status.success(), "{text}");
    assert!(text.contains(expect) && !text.contains("skipped"), "{text}");
}

#[test]
fn c3d_files_round_trip_with_ezc3d() {
    pytest("tests/c3d_interop.py", "ezc3d, numpy, pytest", "3 passed");
}

#[test]
fn ros2_interface_definitions_parse_with_rosbags() {
    pytest("tests/msg_defs.py", "rosbags, numpy, pytest", "2 passed");
}
