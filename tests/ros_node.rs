//! The node against an independent DDS implementation (Eclipse Cyclone DDS
//! through its Python binding, tests/ros_interop.py): topics, namespaces and
//! remaps, params files, obstacles and pins, bad input, services, the ROS 2
//! parameter services and a streamed body (garment_sim_msgs/Body and
//! mesh_msgs/MeshGeometryStamped). Everything runs in a network namespace made for the
//! test (`unshare -rn`: only a loopback interface), so no packet leaves it.

mod support;

#[test]
fn node_interoperates_with_cyclone_dds() {
    let dir = support::Scratch::new("ros_node");
    let uri = support::cyclone_loopback_uri(&dir);
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    support::pytest(
        "tests/ros_interop.py",
        "cyclonedds, numpy, pytest",
        true,
        &[("GARMENT_SIM_BIN", &bin), ("CYCLONEDDS_URI", &uri)],
        "8 passed",
    );
}
