//! Bursts of undecodable and refused messages against the node, from an
//! independent DDS implementation (Eclipse Cyclone DDS through its Python
//! binding, tests/ros_burst.py), with the node's stderr a pipe nobody reads:
//! it keeps its pace and publishes on time, counts every message, logs a
//! few lines a second and applies the valid messages after each burst.
//! `GARMENT_SIM_BURSTS` (default 10) is the number of bursts. And a
//! subscriber that stops (SIGSTOP) does not hold the node. Everything
//! runs in a network namespace made for the test (`unshare -rn`: only a
//! loopback interface), so no packet leaves it.

mod support;

#[test]
fn bursts_of_bad_messages_and_a_stopped_subscriber_do_not_hold_the_node() {
    let dir = support::Scratch::new("ros_burst");
    let uri = support::cyclone_loopback_uri(&dir);
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    let bursts = std::ffi::OsString::from(
        std::env::var("GARMENT_SIM_BURSTS").unwrap_or_else(|_| "10".into()),
    );
    support::pytest(
        "tests/ros_burst.py",
        "cyclonedds, numpy, pytest",
        true,
        &[
            ("GARMENT_SIM_BIN", &bin),
            ("CYCLONEDDS_URI", &uri),
            ("GARMENT_SIM_BURSTS", &bursts),
        ],
        "2 passed",
    );
}
