//! Runs the C3D interoperability tests against the independent `ezc3d`
//! implementation (tests/c3d_interop.py). Its Python packages come from
//! tests/requirements.txt, which .ci/run installs; without them this test
//! fails and says what to install (it never passes silently).

use std::process::Command;

#[test]
fn c3d_files_round_trip_with_ezc3d() {
    let probe = Command::new("python3")
        .args(["-c", "import ezc3d, numpy, pytest"])
        .output()
        .expect("python3 is needed for the C3D interop test");
    assert!(
        probe.status.success(),
        "the C3D interop test needs Python packages: python3 -m pip install -r tests/requirements.txt\n{}",
        String::from_utf8_lossy(&probe.stderr)
    );
    let out = Command::new("python3")
        .args(["-m", "pytest", "-q", "-rs", "tests/c3d_interop.py"])
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("3 passed") && !text.contains("skipped"),
        "{text}"
    );
}
