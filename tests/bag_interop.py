"""garment_sim bags against independent readers: `rosbags` (rosbag2 reader,
its own CDR deserialiser with types built from the bag's own schemas) and
`mcap` + `mcap-ros2-support`. Run by tests/bags.rs inside a network namespace
it makes (loopback only: the node starts DDS), with:

GARMENT_SIM_BIN       the garment_sim binary
GARMENT_SIM_EXPECTED  the cloth trajectory stepped in-process by tests/bags.rs
                      (table drape, 2 cm, dt 4 ms, 0.3 s, frames at 30 Hz)
GARMENT_SIM_TMP       a scratch directory
"""

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

BIN = os.environ.get("GARMENT_SIM_BIN")
TMP = Path(os.environ.get("GARMENT_SIM_TMP", "/tmp"))
SCENE = "config/scenes/table_drape.yaml"
TOPICS = {
    "/cloth/points": "sensor_msgs/msg/PointCloud2",
    "/cloth/mesh": "visualization_msgs/msg/Marker",
    "/obstacles/markers": "visualization_msgs/msg/MarkerArray",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/scene_description": "std_msgs/msg/String",
}

if BIN is None:
    pytest.skip("run through tests/bags.rs (GARMENT_SIM_BIN)", allow_module_level=True)

EXP = json.loads(Path(os.environ["GARMENT_SIM_EXPECTED"]).read_text())
EXP_T = np.array(EXP["times"])
EXP_X = [np.array(p).reshape(-1, 3) for p in EXP["positions"]]
# the default solver (`auto`): its choice depends on iteration counts only,
# so runs are reproducible bit for bit
RUN = ["--spacing", str(EXP["spacing"]), "--dt", str(EXP["dt"])]


def ns(t):
    return int(round(t * 1e9))


def drape(bag, *extra, duration=None, out=None):
    out = out or bag.parent / (bag.name + "_out")
    cmd = [BIN, "drape", SCENE, *RUN, "--duration", str(duration or EXP["duration"]),
           "--out", str(out), "--bag", str(bag), "--bag-rate", str(EXP["rate"]), *extra]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return out, r


_headless = {}


def headless(compression="zstd"):
    """The reference bag, written once per compression."""
    if compression not in _headless:
        bag = TMP / f"headless_{compression}"
        out, _ = drape(bag, "--bag-compression", compression)
        _headless[compression] = (bag, out)
    return _headless[compression]


def mcap_file(bag):
    files = list(bag.glob("*.mcap"))
    assert len(files) == 1, files
    return files[0]


def metadata(bag):
    return yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def cloud_xyz(msg):
    """x, y, z of a PointCloud2 with float32 fields x y z strain speed."""
    names = [f.name for f in msg.fields]
    assert names == ["x", "y", "z", "strain", "speed"], names
    assert msg.point_step == 20 and msg.height == 1 and not msg.is_bigendian
    a = np.frombuffer(bytes(msg.data), dtype="<f4").reshape(msg.width, 5)
    return a[:, :3].astype(np.float64)


def check_against_expected(times_ns, clouds, upto=None):
    """Frames (stamps, positions) equal the in-process trajectory."""
    n = len(EXP_T) if upto is None else int(np.searchsorted(EXP_T, upto + 1e-9))
    assert len(times_ns) >= n, (len(times_ns), n)
    for k in range(n):
        assert times_ns[k] == ns(EXP_T[k]), (k, times_ns[k], EXP_T[k])
        x = clouds[k]
        assert x.shape == EXP_X[k].shape
        # float32 in the cloud: within its rounding of the float64 state
        err = np.abs(x - EXP_X[k]).max()
        assert err <= 1e-6 * max(1.0, np.abs(EXP_X[k]).max()), (k, err)
    return n


def read_rosbags(bag):
    """Every message through rosbags, deserialised with types built only from
    the bag's own schemas: {topic: [(log time, stamp ns or None, msg)]}."""
    ts = get_typestore(Stores.EMPTY)
    out = {}
    with Rosbag2Reader(bag) as r:
        for c in r.connections:
            assert c.msgdef.data, c.topic
            ts.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        conns = {c.topic: c for c in r.connections}
        for c, t, raw in r.messages():
            m = ts.deserialize_cdr(raw, c.msgtype)
            st = getattr(m, "header", None)
            stamp = st.stamp.sec * 10**9 + st.stamp.nanosec if st is not None else None
            out.setdefault(c.topic, []).append((t, stamp, m))
        return out, conns, r.message_count


# ---------------------------------------------------------------------------


def test_headless_bag_reads_in_rosbags_with_its_own_schemas():
    bag, out = headless()
    msgs, conns, count = read_rosbags(bag)
    md = metadata(bag)
    assert md["storage_identifier"] == "mcap" and md["version"] <= 9
    assert md["relative_file_paths"] == [mcap_file(bag).name]
    assert {c: conns[c].msgtype for c in conns} == TOPICS
    # each schema defines its type and dependencies field for field (and
    # constant for constant) as rosbags' own ROS 2 Jazzy type store does
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    for c in conns.values():
        for name, (consts, fields) in get_types_from_msg(c.msgdef.data, c.msgtype).items():
            jconsts, jfields = jazzy.fielddefs[name]
            assert fields == jfields, name
            assert sorted(consts) == sorted(jconsts), name
    per_topic = {t["topic_metadata"]["name"]: t["message_count"] for t in md["topics_with_message_count"]}
    assert per_topic == {k: len(v) for k, v in msgs.items()}
    assert count == md["message_count"] == sum(per_topic.values())
    n = len(EXP_T)
    for topic in ["/cloth/points", "/cloth/mesh", "/diagnostics", "/clock", "/obstacles/markers"]:
        assert len(msgs[topic]) == n, topic
    # stamps: log time = header stamp = simulated time
    clouds = msgs["/cloth/points"]
    assert all(t == s for t, s, _ in clouds)
    assert all(m.header.frame_id == "world" for _, _, m in clouds)
    check_against_expected([t for t, _, _ in clouds], [cloud_xyz(m) for _, _, m in clouds])
    # the mesh marker carries float64 vertices of the same state, as triangles
    t, _, mk = msgs["/cloth/mesh"][-1]
    assert mk.type == 11 and len(mk.points) % 3 == 0
    nx, ny = EXP["nx"], EXP["ny"]
    assert len(mk.points) == 3 * 2 * (nx - 1) * (ny - 1)
    pts = np.array([[p.x, p.y, p.z] for p in mk.points])
    last = EXP_X[-1]
    d = np.min(np.linalg.norm(pts[:, None, :] - last[None, ::7, :], axis=2), axis=0)
    assert d.max() < 1e-12  # every sampled vertex is a marker point, exactly
    clock = [m.clock.sec * 10**9 + m.clock.nanosec for _, _, m in msgs["/clock"]]
    assert clock == [t for t, _, _ in clouds]
    # the scene description explains the bag
    (_, _, d), = msgs["/scene_description"]
    desc = yaml.safe_load(d.data)
    assert desc["grid"] == [nx, ny] and abs(desc["dt_s"] - EXP["dt"]) < 1e-15
    assert "areal_mass" in desc["fabric_yaml"] and "obstacles" in desc["scene_yaml"]
    # and the last frame is the drape's final.ply
    lines = (out / "final.ply").read_text().splitlines()
    nv = int(next(line for line in lines if line.startswith("element vertex")).split()[2])
    body = lines[lines.index("end_header") + 1:]
    ply = np.array([[float(v) for v in line.split()[:3]] for line in body[:nv]])
    assert np.abs(ply - EXP_X[-1]).max() < 1e-12


def test_headless_bag_reads_in_mcap_with_ros2_decoder():
    for comp in ["zstd", "lz4"]:
        bag, _ = headless(comp)
        md = metadata(bag)
        qos_md = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
                  for t in md["topics_with_message_count"]}
        with open(mcap_file(bag), "rb") as f:
            r = make_reader(f, decoder_factories=[DecoderFactory()])
            assert r.get_header().profile == "ros2"
            s = r.get_summary()
            assert s is not None and s.statistics.message_count == md["message_count"]
            assert {c.compression for c in s.chunk_indexes} == {comp}
            for ch in s.channels.values():
                sc = s.schemas[ch.schema_id]
                assert sc.encoding == "ros2msg" and ch.message_encoding == "cdr"
                assert TOPICS[ch.topic] == sc.name
                # the same QoS in metadata.yaml and on the channel (rosbags needs it)
                assert yaml.safe_load(ch.metadata["offered_qos_profiles"]) == qos_md[ch.topic], ch.topic
            assert any(m.name == "rosbag2" for m in r.iter_metadata())
            times, clouds = [], []
            for _, ch, msg, dec in r.iter_decoded_messages(topics=["/cloth/points"]):
                assert msg.log_time == msg.publish_time
                times.append(msg.log_time)
                clouds.append(cloud_xyz(dec))
        check_against_expected(times, clouds)


def test_bag_info_and_export():
    bag, out = headless()
    r = subprocess.run([BIN, "bag", "info", str(bag)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    n = len(EXP_T)
    assert f"Topic: /cloth/points | Type: sensor_msgs/msg/PointCloud2 | Count: {n}" in r.stdout, r.stdout
    assert "complete" in r.stdout
    assert f"Duration:          {EXP_T[-1]:.9f} s" in r.stdout, r.stdout
    # a frame in the middle as OBJ (float64 positions from the mesh marker)
    k = n // 2
    obj = TMP / "mid.obj"
    r = subprocess.run([BIN, "bag", "export", str(bag), "--time", f"{EXP_T[k] + 0.001:.6f}",
                        "--format", "obj", "--out", str(obj)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    v = np.array([[float(a) for a in line.split()[1:]] for line in obj.read_text().splitlines()
                  if line.startswith("v ")])
    f = [line for line in obj.read_text().splitlines() if line.startswith("f ")]
    assert np.abs(v - EXP_X[k]).max() < 1e-12
    assert len(f) == 2 * (EXP["nx"] - 1) * (EXP["ny"] - 1)
    # the last frame as PLY
    ply = TMP / "last.ply"
    r = subprocess.run([BIN, "bag", "export", str(bag), "--last", "--out", str(ply)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = ply.read_text().splitlines()
    body = lines[lines.index("end_header") + 1:]
    x = np.array([[float(a) for a in line.split()] for line in body[:len(EXP_X[-1])]])
    assert np.abs(x - EXP_X[-1]).max() < 1e-12
    # a time outside the bag, a missing bag: clear errors
    r = subprocess.run([BIN, "bag", "export", str(bag), "--time", "7", "--out", str(TMP / "x.ply")],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "outside the bag" in r.stderr, r.stderr
    r = subprocess.run([BIN, "bag", "info", str(TMP / "no_such_bag")], capture_output=True, text=True)
    assert r.returncode != 0 and "no such bag" in r.stderr, r.stderr
    # a bag is never overwritten
    r = subprocess.run([BIN, "drape", SCENE, *RUN, "--duration", "0.01", "--out", str(TMP / "o"),
                        "--bag", str(bag)], capture_output=True, text=True)
    assert r.returncode != 0 and "already exists" in r.stderr, r.stderr


def wait_for_messages(p, bag, at_least, timeout=120):
    """Waits until the running process `p` has flushed at least `at_least`
    messages into `bag` (as metadata.yaml, rewritten per chunk, says);
    returns that count."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            count = metadata(bag)["message_count"]
        except (FileNotFoundError, TypeError, KeyError, yaml.YAMLError):
            count = 0
        if count >= at_least:
            return count
        assert p.poll() is None, p.communicate()
        time.sleep(0.05)
    p.kill()
    raise AssertionError(f"{bag} never held {at_least} messages")


def wait_delivered(pid, sig, timeout=10.0):
    """Waits until signal `sig` sent to process `pid` is no longer pending
    (its thread-directed or process-wide pending masks in /proc)."""
    bit = 1 << (sig - 1)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with open(f"/proc/{pid}/status") as f:
            fields = dict(line.split(":", 1) for line in f if ":" in line)
        pending = int(fields["SigPnd"], 16) | int(fields["ShdPnd"], 16)
        if not pending & bit:
            return
        time.sleep(0.0002)
    raise AssertionError(f"signal {sig} still pending for process {pid} after {timeout} s")


def start_long_drape(bag):
    """A long drape recording every step in small chunks, signalled once it
    has flushed chunks: returns the process and the metadata count then."""
    cmd = [BIN, "drape", SCENE, *RUN, "--duration", "60", "--out", str(bag.parent / (bag.name + "_out")),
           "--bag", str(bag), "--bag-rate", "1000", "--bag-chunk-size", "65536"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return p, wait_for_messages(p, bag, 60)


def clouds_mcap_stream(path):
    """Clouds read linearly with mcap's non-seeking reader (no summary needed)
    until the file ends: (times, positions, error at the end or None)."""
    times, clouds, err = [], [], None
    dec = DecoderFactory()
    decoders = {}
    with open(path, "rb") as f:
        try:
            for sc, ch, msg in NonSeekingReader(f).iter_messages(log_time_order=False):
                if ch.topic != "/cloth/points":
                    continue
                if ch.id not in decoders:
                    decoders[ch.id] = dec.decoder_for(ch.message_encoding, sc)
                times.append(msg.log_time)
                clouds.append(cloud_xyz(decoders[ch.id](msg.data)))
        except Exception as e:  # the cut at the end of a killed bag
            err = e
    return times, clouds, err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sigint_and_sigterm_leave_a_complete_bag(sig):
    bag = TMP / f"signal_{int(sig)}"
    p, _ = start_long_drape(bag)
    p.send_signal(sig)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, out + err
    assert "stopped by a signal" in err, err
    summary = json.loads((bag.parent / (bag.name + "_out") / "summary.json").read_text())
    assert summary["simulated_s"] < 60
    msgs, _, count = read_rosbags(bag)
    md = metadata(bag)
    assert count == md["message_count"] == sum(len(v) for v in msgs.values())
    clouds = msgs["/cloth/points"]
    # every step recorded, up to the state the run stopped in
    assert clouds[-1][0] == ns(summary["simulated_s"])
    assert len(clouds) == summary["steps"] + 1
    ts = [t for t, _, _ in clouds]
    # at 1000 Hz every 4 ms step is a frame: compare those at the 30 Hz frame times
    idx = [ts.index(ns(t)) for t in EXP_T if ns(t) <= ts[-1]]
    assert len(idx) >= 2
    check_against_expected([ts[i] for i in idx], [cloud_xyz(clouds[i][2]) for i in idx],
                           upto=ts[idx[-1]] * 1e-9)
    with open(mcap_file(bag), "rb") as f:
        s = make_reader(f).get_summary()
        assert s is not None and len(s.chunk_indexes) > 1
    info = subprocess.run([BIN, "bag", "info", str(bag)], capture_output=True, text=True)
    assert "complete" in info.stdout and "problem" not in info.stdout.lower(), info.stdout


def test_a_second_sigint_while_the_bag_closes_still_finishes_it():
    """A second SIGINT as soon as the first has been delivered (while the run
    stops, writes its outputs and closes the bag; two signals sent at once are
    merged into one by the kernel): the bag is finished all the same, its metadata.yaml lists
    every message rosbags reads, and the program says it was interrupted
    again."""
    bag = TMP / "signal_twice"
    p, _ = start_long_drape(bag)
    os.kill(p.pid, signal.SIGINT)
    # the second once the first has been delivered (no longer pending): a
    # fixed delay either merged the two on a busy host or came after the
    # close on a fast one (it takes under 20 ms there)
    wait_delivered(p.pid, signal.SIGINT)
    os.kill(p.pid, signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, out + err
    assert "interrupted again while it was being closed" in err, err
    msgs, _, count = read_rosbags(bag)
    md = metadata(bag)
    assert count == md["message_count"] == sum(len(v) for v in msgs.values())
    summary = json.loads((bag.parent / (bag.name + "_out") / "summary.json").read_text())
    assert msgs["/cloth/points"][-1][0] == ns(summary["simulated_s"])
    with open(mcap_file(bag), "rb") as f:
        s = make_reader(f).get_summary()
        assert s is not None and sum(s.statistics.channel_message_counts.values()) == count


def test_sigkill_leaves_a_bag_readable_to_its_last_chunk_and_repair_rebuilds_it():
    bag = TMP / "killed"
    p, before = start_long_drape(bag)
    p.kill()
    p.communicate(timeout=60)
    assert p.returncode == -signal.SIGKILL
    md = metadata(bag)  # still a valid metadata.yaml, describing whole chunks
    assert md["message_count"] >= before
    # readable with an independent reader up to the cut
    times, clouds, err = clouds_mcap_stream(mcap_file(bag))
    n_cloud_md = {t["topic_metadata"]["name"]: t["message_count"]
                  for t in md["topics_with_message_count"]}["/cloth/points"]
    assert len(times) >= n_cloud_md > 0
    # every step is a frame (1000 Hz > 1/dt): the ones at the 30 Hz times match
    idx = [times.index(ns(t)) for t in EXP_T if ns(t) <= times[-1]]
    assert len(idx) >= 2
    exp_n = len(idx)
    for k, i in enumerate(idx):
        assert np.abs(clouds[i] - EXP_X[k]).max() <= 1e-6
    info = subprocess.run([BIN, "bag", "info", str(bag)], capture_output=True, text=True)
    assert info.returncode == 0 and "truncated" in info.stdout.lower(), info.stdout
    r = subprocess.run([BIN, "bag", "repair", str(bag)], capture_output=True, text=True)
    assert r.returncode == 0 and "repaired" in r.stdout, r.stdout + r.stderr
    msgs, _, count = read_rosbags(bag)
    md2 = metadata(bag)
    assert count == md2["message_count"] >= md["message_count"]
    ts = [t for t, _, _ in msgs["/cloth/points"]]
    assert ts == times[:len(ts)] and len(ts) >= n_cloud_md
    assert exp_n >= 2
    with open(mcap_file(bag), "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == count
    info = subprocess.run([BIN, "bag", "info", str(bag)], capture_output=True, text=True)
    assert "complete" in info.stdout, info.stdout


def node(bag, *params, duration=None):
    args = [BIN, "node", "--ros-args", "-p", f"scene:={SCENE}", "-p", f"spacing:={EXP['spacing']}",
            "-p", f"dt:={EXP['dt']}", "-p", "real_time_factor:=0.0", "-p", f"publish_rate:={EXP['rate']}",
            "-p", f"record_bag:={bag}",
            # the headless drape's thread count (its default, one per core):
            # the node's default is one thread
            "-p", "threads:=0", *params]
    if duration is not None:
        args += ["-p", f"duration:={duration}"]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_node_records_the_same_trajectory_as_a_headless_run():
    hb, _ = headless()
    nb = TMP / "node_bag"
    p = node(nb, duration=EXP["duration"])
    out, err = p.communicate(timeout=120)
    assert p.returncode == 0, out + err
    node_msgs, conns, count = read_rosbags(nb)
    head_msgs, _, _ = read_rosbags(hb)
    assert {c: conns[c].msgtype for c in conns} == TOPICS
    assert count == metadata(nb)["message_count"]
    a = node_msgs["/cloth/points"]
    b = head_msgs["/cloth/points"]
    assert [t for t, _, _ in a] == [t for t, _, _ in b]
    for (_, _, ma), (_, _, mb) in zip(a, b):
        assert np.array_equal(cloud_xyz(ma), cloud_xyz(mb))
    check_against_expected([t for t, _, _ in a], [cloud_xyz(m) for _, _, m in a])
    # the node offers what the bag says it offered
    md = metadata(nb)
    q = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"][0]
         for t in md["topics_with_message_count"]}
    assert q["/scene_description"]["durability"] == "transient_local"
    assert q["/cloth/points"]["reliability"] == "reliable" and q["/cloth/points"]["depth"] == 10


def test_node_stopped_by_sigterm_leaves_a_complete_bag():
    nb = TMP / "node_sigterm"
    p = node(nb)  # runs until stopped
    wait_for_messages(p, nb, 16, timeout=60)  # at least 3 frames of 5 messages and the description
    # metadata.yaml is rewritten per chunk; give the node a moment of simulated time
    time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, out + err
    msgs, _, count = read_rosbags(nb)
    assert count == metadata(nb)["message_count"]
    a = msgs["/cloth/points"]
    assert len(a) >= 2
    check_against_expected([t for t, _, _ in a], [cloud_xyz(m) for _, _, m in a],
                           upto=min(EXP_T[-1], a[-2][0] * 1e-9))
    with open(mcap_file(nb), "rb") as f:
        assert make_reader(f).get_summary() is not None


def test_node_in_a_namespace_killed_leaves_a_repairable_bag():
    nb = TMP / "node_killed"
    p = node(nb, "-r", "__ns:=/lab")  # runs until stopped
    before = wait_for_messages(p, nb, 30, timeout=60)
    p.kill()
    p.communicate(timeout=60)
    md = metadata(nb)
    assert md["message_count"] >= before
    names = {t["topic_metadata"]["name"] for t in md["topics_with_message_count"]}
    assert "/lab/cloth/points" in names and "/clock" in names, names
    r = subprocess.run([BIN, "bag", "repair", str(nb)], capture_output=True, text=True)
    assert r.returncode == 0 and "repaired" in r.stdout, r.stdout + r.stderr
    msgs, _, count = read_rosbags(nb)
    assert count == metadata(nb)["message_count"] >= md["message_count"]
    a = msgs["/lab/cloth/points"]
    check_against_expected([t for t, _, _ in a], [cloud_xyz(m) for _, _, m in a],
                           upto=min(EXP_T[-1], a[-1][0] * 1e-9))
    # export finds the namespaced cloth topics by themselves
    ply = TMP / "node_last.ply"
    r = subprocess.run([BIN, "bag", "export", str(nb), "--last", "--out", str(ply)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert f"{EXP['nx'] * EXP['ny']} vertices, {2 * (EXP['nx'] - 1) * (EXP['ny'] - 1)} triangles" in r.stdout, r.stdout
