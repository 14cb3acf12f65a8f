//! What the Python interoperability tests share: a check that the Python
//! packages are there (failing with what to install, never passing
//! silently), and running a pytest file, optionally inside a network
//! namespace made for the test (`unshare -rn`: only a loopback interface,
//! with multicast for DDS discovery), so that no packet leaves it.

use std::ffi::OsStr;
use std::process::Command;

/// Fails unless `python3 -c "import MODULES"` works.
pub fn require_python(modules: &str) {
    let probe = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .expect("python3 is needed for the interoperability tests");
    assert!(
        probe.status.success(),
        "needs Python packages ({modules}): python3 -m pip install -r tests/requirements.txt\n{}",
        String::from_utf8_lossy(&probe.stderr)
    );
}

/// Runs `python3 -m pytest FILE` (in a loopback-only network namespace if
/// `netns`) with `envs`, prints its output and asserts that it passed with
/// `expect` (e.g. "5 passed") in its output and nothing skipped.
pub fn pytest(file: &str, modules: &str, netns: bool, envs: &[(&str, &OsStr)], expect: &str) {
    require_python(modules);
    let mut cmd = if netns {
        let script = format!(
            "ip link set lo up && ip link set lo multicast on && \
             ip route add 224.0.0.0/4 dev lo && exec python3 -m pytest -q -s -rs {file}"
        );
        let mut c = Command::new("unshare");
        c.args(["-rn", "sh", "-c", &script]);
        c
    } else {
        let mut c = Command::new("python3");
        c.args(["-m", "pytest", "-q", "-s", "-rs", file]);
        c
    };
    for (k, v) in envs {
        cmd.env(k, v);
    }
    let out = cmd
        .env_remove("ROS_DOMAIN_ID")
        .output()
        .expect("python3 (and for network tests unshare and ip) are needed");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(out.status.success(), "{text}");
    assert!(text.contains(expect) && !text.contains("skipped"), "{text}");
}
