// The live view's independent client (tests/live_view.rs runs it): connects
// to a Foxglove WebSocket server with Foxglove's own protocol client,
// subscribes to every advertised channel, decodes each message from the
// channel's advertised ros2msg schema with Foxglove's ROS 2 parser and CDR
// reader, and prints what it saw as JSON on stdout.
//
// usage: node client.js URL FINAL_TIME_S TIMEOUT_S
// It closes the connection once it has both the /clock message stamped
// FINAL_TIME_S (the last message of the run's last frame) and the server's
// time broadcast of FINAL_TIME_S, and fails after TIMEOUT_S. (The server
// broadcasts a frame's time before it logs the frame's messages, but the two
// reach a client by different queues: under load a frame's messages can
// arrive before its time: the Foxglove SDK sends the time on each client's
// control queue, the messages on its data queue.)

"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const WebSocket = require("ws");

const [url, finalArg, timeoutArg] = process.argv.slice(2);
if (!url || finalArg === undefined || timeoutArg === undefined) {
  console.error("usage: node client.js URL FINAL_TIME_S TIMEOUT_S");
  process.exit(2);
}
const finalNs = BigInt(Math.round(Number(finalArg) * 1e9));

const stampNs = (t) => BigInt(t.sec) * 1000000000n + BigInt(t.nanosec);

const out = {
  server: null,
  channels: [],
  trailing_bytes: 0,
  times_ns: [],
  clouds: [],
  first_cloud: null,
  last_cloud: null,
  meshes: [],
  last_mesh_points: null,
  obstacles: null,
  diagnostics: null,
  clock_ns: [],
};
const bySubscription = new Map();

// The x, y, z of every point of a PointCloud2, from its own field table.
function cloudPoints(msg) {
  const field = (name) => {
    const f = msg.fields.find((f) => f.name === name);
    if (!f) throw new Error(`cloud has no field ${name}`);
    if (f.datatype !== 7) throw new Error(`field ${name} is not FLOAT32`);
    return f.offset;
  };
  const [ox, oy, oz] = ["x", "y", "z"].map(field);
  const data = msg.data;
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const little = !msg.is_bigendian;
  const points = [];
  for (let i = 0; i < msg.width * msg.height; i++) {
    const b = i * msg.point_step;
    points.push([
      view.getFloat32(b + ox, little),
      view.getFloat32(b + oy, little),
      view.getFloat32(b + oz, little),
    ]);
  }
  return points;
}

const timer = setTimeout(() => {
  console.error(`no final frame (t = ${finalArg} s) within ${timeoutArg} s`);
  console.error(JSON.stringify({ ...out, first_cloud: null, last_cloud: null, last_mesh_points: null }));
  process.exit(3);
}, Number(timeoutArg) * 1000);

const client = new FoxgloveClient({
  ws: new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});

client.on("error", (e) => {
  console.error(`client error: ${e && e.message ? e.message : e}`);
  process.exit(4);
});

client.on("serverInfo", (info) => {
  out.server = { name: info.name, capabilities: info.capabilities };
});

let finalClock = false;
let finalTime = false;
let done = false;
function finishIfComplete() {
  if (done || !(finalClock && finalTime)) return;
  done = true;
  clearTimeout(timer);
  client.close();
  process.stdout.write(JSON.stringify(out) + "\n");
}

client.on("time", ({ timestamp }) => {
  out.times_ns.push(timestamp.toString());
  if (BigInt(timestamp) >= finalNs) {
    finalTime = true;
    finishIfComplete();
  }
});

client.on("advertise", (channels) => {
  // the cloud last: the server starts once a channel is subscribed
  const order = [...channels].sort(
    (a, b) => (a.topic === "/cloth/points") - (b.topic === "/cloth/points"),
  );
  for (const ch of order) {
    out.channels.push({
      topic: ch.topic,
      encoding: ch.encoding,
      schema_name: ch.schemaName,
      schema_encoding: ch.schemaEncoding,
    });
    if (ch.encoding !== "cdr" || ch.schemaEncoding !== "ros2msg") continue;
    const reader = new MessageReader(parse(ch.schema, { ros2: true }));
    const id = client.subscribe(ch.id);
    bySubscription.set(id, { topic: ch.topic, reader });
  }
});

client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = bySubscription.get(subscriptionId);
  if (!sub) return;
  const msg = sub.reader.readMessage(data);
  if (sub.reader.lastReadHadTrailingBytes()) out.trailing_bytes += 1;
  const logNs = timestamp.toString();
  switch (sub.topic) {
    case "/cloth/points": {
      const points = cloudPoints(msg);
      out.clouds.push({
        log_ns: logNs,
        stamp_ns: stampNs(msg.header.stamp).toString(),
        frame_id: msg.header.frame_id,
        width: msg.width,
        height: msg.height,
        fields: msg.fields.map((f) => f.name),
      });
      if (out.first_cloud === null) out.first_cloud = points;
      out.last_cloud = points;
      break;
    }
    case "/cloth/mesh":
      out.meshes.push({
        stamp_ns: stampNs(msg.header.stamp).toString(),
        type: msg.type,
        points: msg.points.length,
        colors: msg.colors.length,
      });
      out.last_mesh_points = msg.points.map((p) => [p.x, p.y, p.z]);
      break;
    case "/obstacles/markers":
      out.obstacles = msg.markers.map((m) => ({
        ns: m.ns,
        id: m.id,
        type: m.type,
        action: m.action,
        text: m.text,
        points: m.points.length,
      }));
      break;
    case "/diagnostics":
      out.diagnostics = msg.status.map((s) => ({
        name: s.name,
        level: s.level,
        message: s.message,
        values: Object.fromEntries(s.values.map((kv) => [kv.key, kv.value])),
      }));
      break;
    case "/clock": {
      const t = stampNs(msg.clock);
      out.clock_ns.push(t.toString());
      if (t >= finalNs) {
        finalClock = true;
        finishIfComplete();
      }
      break;
    }
  }
});
