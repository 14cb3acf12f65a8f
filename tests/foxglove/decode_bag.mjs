// Decodes every message of a rosbag2 MCAP bag with the decoders the Foxglove
// app uses: @mcap/core's reader (with @mcap/support's decompression handlers),
// @foxglove/rosmsg's `parse(schema, { ros2: true })` for each channel's
// `ros2msg` schema and @foxglove/rosmsg2-serialization's MessageReader for its
// CDR messages. Prints one JSON object on stdout:
//
//   { files, profile, library, reader, statistics_message_count,
//     decoded_messages, trailing_bytes,
//     channels: [{ topic, schema_name, schema_encoding, message_encoding, count,
//                  first_log_time, last_log_time }],
//     counts: { topic: n },
//     last_cloud: { topic, log_time, stamp, frame_id, width, height,
//                   point_step, fields: [name], xyz: [[x, y, z], ...] } }
//
// `last_cloud` is the last message on a topic ending in `cloth/points`, its
// points read from `data` through its PointField descriptions. Any channel
// whose schema does not parse, or any message that does not decode, ends the
// script with a non-zero exit status and the reason on stderr.
//
// Usage: node decode_bag.mjs [--stream] BAGDIR_OR_MCAP
//   --stream  read with McapStreamReader (front to back, no index) instead of
//             McapIndexedReader (summary and chunk indexes)

import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { open, readFile, readdir, stat } from "node:fs/promises";
import path from "node:path";

function fail(msg) {
  process.stderr.write(`decode_bag: ${msg}\n`);
  process.exit(1);
}

const args = process.argv.slice(2);
const stream = args.includes("--stream");
const targets = args.filter((a) => a !== "--stream");
if (targets.length !== 1) {
  fail("usage: node decode_bag.mjs [--stream] BAGDIR_OR_MCAP");
}

async function mcapFiles(target) {
  const st = await stat(target);
  if (!st.isDirectory()) {
    return [target];
  }
  const names = (await readdir(target)).filter((n) => n.endsWith(".mcap")).sort();
  if (names.length === 0) {
    fail(`no .mcap file in ${target}`);
  }
  return names.map((n) => path.join(target, n));
}

// PointField datatypes (sensor_msgs/msg/PointField constants).
const FIELD_READERS = {
  1: (v, o, le) => v.getInt8(o),
  2: (v, o, le) => v.getUint8(o),
  3: (v, o, le) => v.getInt16(o, le),
  4: (v, o, le) => v.getUint16(o, le),
  5: (v, o, le) => v.getInt32(o, le),
  6: (v, o, le) => v.getUint32(o, le),
  7: (v, o, le) => v.getFloat32(o, le),
  8: (v, o, le) => v.getFloat64(o, le),
};

function cloudXyz(msg) {
  const byName = new Map(msg.fields.map((f) => [f.name, f]));
  const get = ["x", "y", "z"].map((n) => {
    const f = byName.get(n);
    if (f === undefined) {
      fail(`point cloud has no field ${n}`);
    }
    const read = FIELD_READERS[f.datatype];
    if (read === undefined) {
      fail(`point cloud field ${n} has unknown datatype ${f.datatype}`);
    }
    return { offset: f.offset, read };
  });
  const data = msg.data;
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const le = !msg.is_bigendian;
  const xyz = [];
  for (let row = 0; row < msg.height; row++) {
    for (let col = 0; col < msg.width; col++) {
      const base = row * msg.row_step + col * msg.point_step;
      if (base + msg.point_step > data.byteLength) {
        fail(`point cloud data holds ${data.byteLength} bytes, too few for its size`);
      }
      xyz.push(get.map((g) => g.read(view, base + g.offset, le)));
    }
  }
  return xyz;
}

// A decoder per channel id of the file being read; per topic, the counts over
// every file; the last cloud.
const decoders = new Map();
const channelIds = new Map();
const channels = new Map();
let decoded = 0;
let trailing = 0;
let lastCloud;

function addChannel(channel, schema) {
  if (schema === undefined) {
    fail(`channel ${channel.topic} has no schema`);
  }
  if (schema.encoding !== "ros2msg" || channel.messageEncoding !== "cdr") {
    fail(
      `channel ${channel.topic}: schema encoding ${schema.encoding}, ` +
        `message encoding ${channel.messageEncoding} (expected ros2msg and cdr)`,
    );
  }
  const text = new TextDecoder().decode(schema.data);
  let reader;
  try {
    reader = new MessageReader(parse(text, { ros2: true }));
  } catch (e) {
    fail(`channel ${channel.topic}: schema ${schema.name} does not parse: ${e.message}`);
  }
  decoders.set(channel.id, reader);
  channelIds.set(channel.id, channel.topic);
  if (channels.has(channel.topic)) {
    return;
  }
  channels.set(channel.topic, {
    topic: channel.topic,
    schema_name: schema.name,
    schema_encoding: schema.encoding,
    message_encoding: channel.messageEncoding,
    count: 0,
    first_log_time: null,
    last_log_time: null,
  });
}

function decode(message) {
  const reader = decoders.get(message.channelId);
  if (reader === undefined) {
    fail(`message on unknown channel ${message.channelId}`);
  }
  const ch = channels.get(channelIds.get(message.channelId));
  let msg;
  try {
    msg = reader.readMessage(message.data);
  } catch (e) {
    fail(`${ch.topic} (${ch.schema_name}), message ${ch.count}: ${e.message}`);
  }
  if (reader.lastReadHadTrailingBytes()) {
    trailing += 1;
  }
  ch.count += 1;
  ch.first_log_time ??= message.logTime.toString();
  ch.last_log_time = message.logTime.toString();
  decoded += 1;
  if (ch.topic.endsWith("cloth/points")) {
    lastCloud = { topic: ch.topic, logTime: message.logTime, msg };
  }
}

const decompressHandlers = await loadDecompressHandlers();
const files = await mcapFiles(targets[0]);
const out = { files, reader: stream ? "McapStreamReader" : "McapIndexedReader" };
let statisticsCount = 0n;

for (const file of files) {
  decoders.clear();
  channelIds.clear();
  if (stream) {
    const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
    reader.append(await readFile(file));
    const schemas = new Map();
    for (let rec; (rec = reader.nextRecord()); ) {
      switch (rec.type) {
        case "Header":
          out.profile = rec.profile;
          out.library = rec.library;
          break;
        case "Schema":
          schemas.set(rec.id, rec);
          break;
        case "Channel":
          if (!decoders.has(rec.id)) {
            addChannel(rec, schemas.get(rec.schemaId));
          }
          break;
        case "Message":
          decode(rec);
          break;
        case "Statistics":
          statisticsCount += rec.messageCount;
          break;
        default:
          break;
      }
    }
    if (!reader.done()) {
      fail(`${file}: the stream reader did not reach the end of the file`);
    }
  } else {
    const fh = await open(file, "r");
    const size = (await fh.stat()).size;
    const readable = {
      size: async () => BigInt(size),
      read: async (offset, length) => {
        const buf = new Uint8Array(Number(length));
        let done = 0;
        while (done < buf.length) {
          const { bytesRead } = await fh.read(buf, done, buf.length - done, Number(offset) + done);
          if (bytesRead === 0) {
            throw new Error(`short read at ${offset} in ${file}`);
          }
          done += bytesRead;
        }
        return buf;
      },
    };
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    out.profile = reader.header.profile;
    out.library = reader.header.library;
    for (const channel of reader.channelsById.values()) {
      addChannel(channel, reader.schemasById.get(channel.schemaId));
    }
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      decode(message);
    }
    if (reader.statistics === undefined) {
      fail(`${file}: no statistics record`);
    }
    statisticsCount += reader.statistics.messageCount;
    await fh.close();
  }
}

out.statistics_message_count = Number(statisticsCount);
out.decoded_messages = decoded;
out.trailing_bytes = trailing;
out.channels = [...channels.values()];
out.counts = Object.fromEntries(out.channels.map((c) => [c.topic, c.count]));
if (lastCloud !== undefined) {
  const m = lastCloud.msg;
  out.last_cloud = {
    topic: lastCloud.topic,
    log_time: lastCloud.logTime.toString(),
    stamp: { sec: m.header.stamp.sec, nanosec: m.header.stamp.nanosec },
    frame_id: m.header.frame_id,
    width: m.width,
    height: m.height,
    point_step: m.point_step,
    fields: m.fields.map((f) => f.name),
    xyz: cloudXyz(m),
  };
}
process.stdout.write(JSON.stringify(out) + "\n");
