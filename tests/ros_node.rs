//! The node against an independent DDS implementation (Eclipse Cyclone DDS
//! through its Python binding, tests/ros_interop.py): topics, namespaces and
//! remaps, params files, obstacles and pins, bad input, services and the ROS 2
//! parameter services. Everything runs in a network namespace made for the
//! test (`unshare -rn`: only a loopback interface), so no packet leaves it.

use std::process::Command;

#[test]
fn node_interoperates_with_cyclone_dds() {
    let probe = Command::new("python3")
        .args(["-c", "import cyclonedds, numpy, pytest"])
        .output()
        .expect("python3 is needed");
    assert!(
        probe.status.success(),
        "needs Python packages: python3 -m pip install -r tests/requirements.txt\n{}",
        String::from_utf8_lossy(&probe.stderr)
    );
    let dir = std::env::temp_dir().join(format!("garment_sim_ros_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("cyclonedds.xml");
    std::fs::write(
        &cfg,
        "<CycloneDDS><Domain id=\"any\"><General><Interfaces>\
         <NetworkInterface name=\"lo\" multicast=\"true\"/>\
         </Interfaces></General></Domain></CycloneDDS>",
    )
    .unwrap();
    // Loopback up with multicast (DDS discovery) inside the new namespace.
    let script = "ip link set lo up && ip link set lo multicast on && \
                  ip route add 224.0.0.0/4 dev lo && \
                  exec python3 -m pytest -q -s -rs -x tests/ros_interop.py";
    let out = Command::new("unshare")
        .args(["-rn", "sh", "-c", script])
        .env("GARMENT_SIM_BIN", env!("CARGO_BIN_EXE_garment_sim"))
        .env("CYCLONEDDS_URI", format!("file://{}", cfg.display()))
        .env_remove("ROS_DOMAIN_ID")
        .output()
        .expect("unshare (util-linux) and ip (iproute2) are needed");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("5 passed") && !text.contains("skipped"),
        "{text}"
    );
}
