"""Bursts of bad messages against the garment_sim node, from Eclipse Cyclone DDS (the
`cyclonedds` Python binding): payloads cut short under the node's own type names
(undecodable) and well-formed messages it must refuse (a NaN pin target, an obstacle
50 m away), 2,000 a run at 250 to 1,000 Hz, GARMENT_SIM_BURSTS runs in a row
(default 10) on one node. The node's stdout and stderr are a pipe that is already
full when it starts and that nobody reads for the first runs: every line the node
wrote itself would block it.

Each run asserts, against what the node publishes: its pace in simulated seconds per
wall second (from /clock) during the burst is within a factor of 2 of its pace just
before it; its clouds keep coming, every frame, at that pace; `rejected_messages`
in `diagnostics` counts every message sent, none is dropped; a valid pin and a
valid obstacle sent right after the burst take effect (the cloud shows the pinned
vertex at its target and the cloth lifted by the obstacle). At the end, what the
node wrote on stderr: a few lines a second, adding up to what was sent.

And a subscriber that stops acknowledging (its process stopped) does not hold the
node's loop.

Run by tests/ros_burst.rs inside a network namespace it makes (loopback only). The
node binary is in GARMENT_SIM_BIN."""

import math
import os
import pathlib
import re
import subprocess
import threading
import time
from dataclasses import dataclass, field

import pytest

pytest.importorskip("cyclonedds")
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from ros_interop import (  # noqa: E402
    RELIABLE, Clock, DiagnosticArray, Header, MarkerArray, Obstacle, Pin, Point, PointCloud2, Pose,
    SolidPrimitive, Twist, Vector3, ros, secs, stamp, xyz,
)

BIN = os.environ.get("GARMENT_SIM_BIN")
RUNS = int(os.environ.get("GARMENT_SIM_BURSTS", "10"))
# undecodable and refused messages a run (half on pins, half on obstacles)
MALFORMED = 1000
REFUSED = 1000
RATES = [1000, 500, 250]  # Hz, run k at RATES[k % 3]
BLOCKED_RUNS = 3  # runs before the node's stderr is read at all
PUBLISH_RATE = 30.0
# the writers of the bursts keep every sample until the node has it
KEEP_ALL = Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000), Policy.History.KeepAll)


# Payloads cut short: the first fields of Pin and Obstacle, nothing after them,
# under the node's type names (on their own participant: the full types are
# registered on the other under the same names).
@dataclass
class PinCut(IdlStruct, typename=ros("garment_sim_msgs", "msg", "Pin")):
    header: Header = field(default_factory=Header)
    operation: t.uint8 = 0


@dataclass
class ObstacleCut(IdlStruct, typename=ros("garment_sim_msgs", "msg", "Obstacle")):
    header: Header = field(default_factory=Header)
    id: str = ""


class BlockedNode:
    """The node with stdout and stderr on a pipe filled to capacity before it
    starts; `drain()` starts reading it."""

    def __init__(self, *ros_args):
        assert BIN, "run through `cargo test --release --test ros_burst`"
        r, w = os.pipe()
        os.set_blocking(w, False)
        self.prefill = 0
        for size in (4096, 512, 64, 8, 1):
            try:
                while True:
                    self.prefill += os.write(w, b"#" * size)
            except BlockingIOError:
                pass
        os.set_blocking(w, True)
        self.proc = subprocess.Popen([BIN, "node", "--ros-args", *ros_args], stdout=w, stderr=w)
        os.close(w)
        self.pipe = r
        self.out = bytearray()
        self.reader_thread = None
        self.dp = DomainParticipant(0)

    def drain(self):
        def read():
            while chunk := os.read(self.pipe, 65536):
                self.out += chunk

        self.reader_thread = threading.Thread(target=read, daemon=True)
        self.reader_thread.start()

    def text(self):
        """What the node wrote (after the prefill)."""
        return bytes(self.out[self.prefill:]).decode(errors="replace")

    def stop(self):
        if self.reader_thread is None:
            self.drain()
        self.proc.terminate()
        try:
            code = self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        self.reader_thread.join(timeout=10)
        return code, self.text()


class Watch:
    """Takes /clock, the clouds, `diagnostics` and the obstacles' markers as they
    come (every 5 ms), each with the wall time it was taken at."""

    def __init__(self, dp):
        q = RELIABLE
        self.readers = [DataReader(dp, Topic(dp, "rt" + n, ty), qos=q)
                        for n, ty in (("/clock", Clock), ("/cloth/points", PointCloud2),
                                      ("/diagnostics", DiagnosticArray), ("/obstacles/markers", MarkerArray))]
        self.clock, self.clouds, self.diags = [], [], []
        self.markers = {}  # obstacle id: its last pose
        self.lock = threading.Lock()
        self.stopped = False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        while not self.stopped:
            ck, cl, dg, mk = (r.take(N=2000) for r in self.readers)
            now = time.time()
            with self.lock:
                for a in mk:
                    for m in a.markers:
                        self.markers[m.text] = m.pose
                self.clock += [(now, secs(m.clock)) for m in ck]
                self.clouds += [(now, stamp(m.header), xyz(m)) for m in cl]
                self.diags += [(now, {kv.key: kv.value for kv in m.status[0].values}) for m in dg]
            time.sleep(0.005)

    def sim_at(self, wall):
        """Simulated time of the last /clock taken by `wall`."""
        with self.lock:
            before = [s for w, s in self.clock if w <= wall]
        assert before, f"no /clock by {wall}"
        return before[-1]

    def pace(self, a, b):
        """Simulated seconds per wall second between the wall times a and b."""
        return (self.sim_at(b) - self.sim_at(a)) / (b - a)

    def clouds_between(self, a, b):
        with self.lock:
            return [(w, s, p) for w, s, p in self.clouds if a <= w <= b]

    def latest_cloud(self):
        with self.lock:
            return self.clouds[-1] if self.clouds else None

    def wait(self, what, pred, timeout):
        end = time.time() + timeout
        while time.time() < end:
            got = pred()
            if got is not None:
                return got
            time.sleep(0.02)
        raise AssertionError(f"{what}: not within {timeout} s")

    def marker(self, text):
        with self.lock:
            return self.markers.get(text)

    def last_diag(self):
        with self.lock:
            return self.diags[-1][1] if self.diags else None


def refused_pin(k):
    # PIN of vertex k to a NaN target: well-formed, refused
    return Pin(header=Header(frame_id="world"), operation=0, vertices=[k % 121],
               targets=[Point(x=math.nan, y=0.0, z=1.0)])


def refused_obstacle(k):
    # a sphere 50 m from the cloth: well-formed, refused (limits.md: at most 2 m beyond it)
    return Obstacle(header=Header(frame_id="world"), id=f"far{k % 7}",
                    pose=Pose(position=Point(x=50.0, y=0.0, z=0.5)),
                    primitives=[SolidPrimitive(type=2, dimensions=[0.05])], primitive_poses=[Pose()])


def hanging_scene(tmp_path):
    """A 50 cm cloth at 5 cm (121 vertices) hanging from two corners, dt = 1 ms:
    it comes back to the same rest after each run's pin and obstacle."""
    fabric = pathlib.Path("config/fabrics/acrylic.yaml").resolve()
    scene = tmp_path / "hanging.yaml"
    scene.write_text(f"name: hanging_for_bursts\ncloth:\n  fabric: {fabric}\n  size: [0.5, 0.5]\n"
                     "  spacing: 0.05\n  pose: { position: [0.0, 0.0, 1.0], rpy: [-1.5707963267948966, 0.0, 0.0] }\n"
                     "pins:\n  - grid: [0, 0]\n  - grid: [10, 0]\ndt: 0.001\nduration: 1000.0\noutput_rate: 30\n")
    return scene


def test_bursts_of_bad_messages_neither_stall_nor_flood_the_node(tmp_path):
    import numpy as np

    n = BlockedNode("-p", f"scene:={hanging_scene(tmp_path)}", "-p", f"publish_rate:={PUBLISH_RATE}",
                    "-p", "threads:=1")
    watch = None
    sent = 0
    started = time.time()
    drained_at = None
    try:
        watch = Watch(n.dp)
        pins = DataWriter(n.dp, Topic(n.dp, "rt/pins", Pin), qos=KEEP_ALL)
        obstacles = DataWriter(n.dp, Topic(n.dp, "rt/obstacles", Obstacle), qos=KEEP_ALL)
        cut = DomainParticipant(0)
        pins_cut = DataWriter(cut, Topic(cut, "rt/pins", PinCut), qos=KEEP_ALL)
        obstacles_cut = DataWriter(cut, Topic(cut, "rt/obstacles", ObstacleCut), qos=KEEP_ALL)
        writers = [pins, obstacles, pins_cut, obstacles_cut]
        watch.wait("the node's first clouds and every writer matched",
                   lambda: True if len(watch.clouds) > 10 and all(w.get_matched_subscriptions() for w in writers)
                   else None, 60)
        time.sleep(1.0)
        # a burst: cut pins, cut obstacles, NaN pins, far obstacles in turn
        kinds = [
            (pins_cut, lambda k: PinCut(header=Header(frame_id="world"))),
            (obstacles_cut, lambda k: ObstacleCut(header=Header(frame_id="world"), id="x")),
            (pins, refused_pin),
            (obstacles, refused_obstacle),
        ]
        per_run = MALFORMED + REFUSED
        for run in range(RUNS):
            if run == BLOCKED_RUNS:
                n.drain()
                drained_at = time.time()
            rate = RATES[run % len(RATES)]
            # the pace before: the last 1.5 s
            a = time.time()
            time.sleep(1.5)
            b = time.time()
            before = watch.pace(a, b)
            for k in range(per_run):
                due = b + k / rate
                wait = due - time.time()
                if wait > 0:
                    time.sleep(wait)
                w, make = kinds[k % 4]
                w.write(make(k // 4))
            c = time.time()
            sent += per_run
            # right after it: a valid pin (the middle vertex 3 cm out of the cloth's
            # plane) and a valid obstacle (a plate rising at 0.2 m/s under its lowest vertex)
            _, _, p = watch.latest_cloud()
            v, u = 60, int(np.argmin(p[:, 2]))
            target = p[v] + np.array([0.0, 0.03, 0.0])
            pins.write(Pin(header=Header(frame_id="world"), operation=0, vertices=[v],
                           targets=[Point(x=float(target[0]), y=float(target[1]), z=float(target[2]))]))
            z0 = float(p[u][2])
            plate = p[u] - np.array([0.0, 0.0, 0.012 + 0.005])
            obstacles.write(Obstacle(header=Header(frame_id="world"), id="lift",
                                     pose=Pose(position=Point(x=float(plate[0]), y=float(plate[1]), z=float(plate[2]))),
                                     primitives=[SolidPrimitive(type=1, dimensions=[0.3, 0.3, 0.01])],
                                     primitive_poses=[Pose()], velocity=Twist(linear=Vector3(z=0.2)),
                                     thickness=0.003, friction=0.3))
            during = watch.pace(b, c)
            clouds = watch.clouds_between(b, c)
            stamps = [s for _, s, _ in clouds]
            gaps = [y - x for x, y in zip(stamps, stamps[1:])]
            cloud_pace = (stamps[-1] - stamps[0]) / (clouds[-1][0] - clouds[0][0])
            print(f"run {run + 1}: {per_run} messages at {rate} Hz in {c - b:.2f} s; pace {before:.3f} before, "
                  f"{during:.3f} during (ratio {during / before:.2f}); {len(clouds)} clouds, largest gap "
                  f"{max(gaps) * 1e3:.1f} ms simulated, cloud pace {cloud_pace:.3f}", flush=True)
            assert 0.5 < during / before < 2.0, (before, during)
            assert 0.5 < cloud_pace / before < 2.0, (before, cloud_pace)
            # every frame: one each 1/30 s of simulated time (dt = 1 ms: 33 or 34 ms)
            assert all(g < 1.0 / PUBLISH_RATE + 1.5e-3 for g in gaps), gaps
            # every message counted: rejected_messages reaches what was sent, and no more
            d = watch.wait(f"rejected_messages = {sent}",
                           lambda: (lambda d: d if d and int(d["rejected_messages"]) >= sent else None)(
                               watch.last_diag()), 20)
            assert int(d["rejected_messages"]) == sent, d
            assert d["dropped_messages"] == "0", d
            # the valid pin and obstacle took effect
            watch.wait(f"vertex {v} at its target {target}",
                       lambda: True if np.abs(watch.latest_cloud()[2][v] - target).max() < 1e-3 else None, 10)
            lifted = watch.wait(f"vertex {u} lifted 3 cm from {z0:.3f} m",
                                lambda: (lambda z: z if z > z0 + 0.03 else None)(float(watch.latest_cloud()[2][u][2])),
                                10)
            print(f"    pin: vertex {v} at its target; obstacle: vertex {u} lifted {1e3 * (lifted - z0):.0f} mm",
                  flush=True)
            # the plate stops where it is and goes, the pin lets go: the cloth hangs again
            obstacles.write(Obstacle(header=Header(frame_id="world"), id="lift", operation=3,
                                     pose=watch.marker("lift")))
            time.sleep(0.1)
            obstacles.write(Obstacle(header=Header(frame_id="world"), id="lift", operation=1))
            pins.write(Pin(header=Header(frame_id="world"), operation=2, vertices=[v]))
            time.sleep(0.5)
        d = watch.last_diag()
        assert int(d["rejected_messages"]) == sent and d["dropped_messages"] == "0", d
    finally:
        if watch:
            watch.stopped = True
        code, out = n.stop()
    total = time.time() - started
    print("\n".join(out.splitlines()[-12:]))
    assert code == 0, out
    lines = out.splitlines()
    # the log: each message rejected is either a line of its own or in a summary
    one_by_one = sum(1 for line in lines if "rejected message on" in line)
    summed = sum(int(m.group(1)) + int(m.group(2)) for m in
                 re.finditer(r"(\d+) rejected as undecodable, (\d+) refused", out))
    lost = sum(int(m.group(1)) for m in re.finditer(r"(\d+) log lines not written", out))
    after_drain = total - (drained_at - started) if drained_at else total
    print(f"stderr: {len(lines)} lines in {total:.0f} s ({one_by_one} refusals one by one, {summed} in summaries, "
          f"{lost} lines lost while stderr was blocked) for {sent} messages rejected")
    if lost == 0:
        assert one_by_one + summed == sent, (one_by_one, summed, sent)
    else:
        assert one_by_one + summed < sent
    # a few lines a second: two topics, each at most 5 lines and a summary a second
    assert len(lines) < 256 + 20 * after_drain, len(lines)
    assert f"{sent} messages rejected, 0 dropped" in out, out[-2000:]


# A subscriber of /clock and the clouds in a process of its own, stopped by the test.
SUBSCRIBER = """
import sys, time
sys.path.insert(0, sys.argv[1])
from ros_interop import RELIABLE, Clock, PointCloud2
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
dp = DomainParticipant(0)
rs = [DataReader(dp, Topic(dp, "rt" + n, ty), qos=RELIABLE) for n, ty in (("/clock", Clock), ("/cloth/points", PointCloud2))]
while not all(r.get_matched_publications() for r in rs):
    time.sleep(0.05)
print("matched", flush=True)
while True:
    for r in rs:
        r.take(N=1000)
    time.sleep(0.01)
"""


def test_a_subscriber_that_stops_does_not_hold_the_node(tmp_path):
    """A subscriber process stopped (SIGSTOP) acknowledges nothing: the node's reliable
    /clock writer fills its send window (8192 samples, about 8 s at 1 kHz) before the
    subscriber's lease runs out. The node's clouds keep coming at its pace for 12 s
    (each second against the pace before), and it logs what it could not send."""
    import signal
    import sys

    n = BlockedNode("-p", f"scene:={hanging_scene(tmp_path)}", "-p", f"publish_rate:={PUBLISH_RATE}",
                    "-p", "threads:=1")
    n.drain()
    sub = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, os.path.dirname(os.path.abspath(__file__))],
                           stdout=subprocess.PIPE, text=True)
    watch = None
    try:
        watch = Watch(n.dp)
        assert sub.stdout.readline().strip() == "matched"
        watch.wait("the node's first clouds", lambda: True if len(watch.clouds) > 10 else None, 60)

        def cloud_pace(a, b):
            c = watch.clouds_between(a, b)
            return (c[-1][1] - c[0][1]) / (c[-1][0] - c[0][0]) if len(c) > 1 else 0.0

        a = time.time()
        time.sleep(2.0)
        before = cloud_pace(a, time.time())
        sub.send_signal(signal.SIGSTOP)
        paces = []
        for _ in range(12):
            a = time.time()
            time.sleep(1.0)
            paces.append(cloud_pace(a, time.time()))
        print(f"cloud pace {before:.3f} before the subscriber stopped, then each second: "
              f"{[round(p, 3) for p in paces]}", flush=True)
        assert all(0.5 < p / before < 2.0 for p in paces), (before, paces)
    finally:
        sub.send_signal(signal.SIGCONT)
        sub.kill()
        sub.wait()
        if watch:
            watch.stopped = True
        code, out = n.stop()
    assert code == 0, out
    # the window did fill: the samples that found it full were counted and logged
    unsent = re.findall(r"(\d+) messages \(samples or service replies\) not sent", out)
    print(f"not sent: {unsent}")
    assert unsent, out[-3000:]
