"""A participant outside the secured graph, from Eclipse Cyclone DDS (the
`cyclonedds` Python binding, without DDS Security): for SECONDS it writes an
obstacle `cyclone_intruder` on rt/obstacles every 0.1 s and reads
rt/cloth/points. Prints one JSON line: the largest number of readers its
writer matched and of writers its reader matched, the clouds it received,
the samples it wrote.

    python3 tests/ros_security/intruder.py SECONDS

Run by tests/ros_security.rs inside its loopback-only network namespace."""

import json
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from ros_interop import RELIABLE, Header, Obstacle, Point, PointCloud2, Pose, SolidPrimitive  # noqa: E402

seconds = float(sys.argv[1])
dp = DomainParticipant(0)
clouds = DataReader(dp, Topic(dp, "rt/cloth/points", PointCloud2), qos=RELIABLE)
w = DataWriter(dp, Topic(dp, "rt/obstacles", Obstacle), qos=RELIABLE)
matched_readers, matched_writers, received, written = 0, 0, 0, 0
end = time.time() + seconds
while time.time() < end:
    w.write(Obstacle(header=Header(frame_id="world"), id="cyclone_intruder",
                     pose=Pose(position=Point(x=0.0, y=0.0, z=1.2)),
                     primitives=[SolidPrimitive(type=2, dimensions=[0.05])], primitive_poses=[Pose()]))
    written += 1
    received += len(clouds.take(N=100))
    matched_readers = max(matched_readers, len(w.get_matched_subscriptions()))
    matched_writers = max(matched_writers, len(clouds.get_matched_publications()))
    time.sleep(0.1)
print(json.dumps({"matched_readers": matched_readers, "matched_writers": matched_writers,
                  "received": received, "written": written}))
