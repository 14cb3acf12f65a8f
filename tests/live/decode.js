// Decodes messages as the Foxglove app decodes a `ros2msg` + `cdr` channel
// of an MCAP file: the schema text parsed by @foxglove/rosmsg (ros2 mode),
// the CDR read by @foxglove/rosmsg2-serialization (tests/live_view.rs runs it
// on a bag's channels).
//
// usage: node decode.js FILE.json, where FILE.json is
//   [{ "topic": ..., "schema_name": ..., "schema": "<ros2msg text>", "data": [bytes] }, ...]
// prints [{ "topic", "error" | "message", "trailing_bytes" }, ...] as JSON.

"use strict";
const fs = require("fs");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const input = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
const out = input.map(({ topic, schema, data }) => {
  try {
    const reader = new MessageReader(parse(schema, { ros2: true }));
    const message = reader.readMessage(Uint8Array.from(data));
    return { topic, message, trailing_bytes: reader.lastReadHadTrailingBytes() };
  } catch (e) {
    return { topic, error: String(e && e.message ? e.message : e) };
  }
});
// typed arrays (uint8[] fields) as plain arrays
const replacer = (_k, v) => (ArrayBuffer.isView(v) ? Array.from(v) : v);
process.stdout.write(JSON.stringify(out, replacer) + "\n");
