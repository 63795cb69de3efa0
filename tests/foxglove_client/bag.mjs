// Reads a camo bag with Foxglove's own libraries, as the Foxglove app opens an MCAP file:
// @mcap/core for the container (zstd chunks via @foxglove/wasm-zstd) and each channel's ros2msg
// schema with @foxglove/rosmsg2-serialization. Prints, per topic suffix named, the count of
// messages read and the last one decoded (arrays as their length and first items), as one JSON object.
//   node bag.mjs BAG.mcap TOPIC_SUFFIX...
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import zstd from "@foxglove/wasm-zstd";

const { parse } = rosmsg;
const { MessageReader } = serialization;
const [path, ...wanted] = process.argv.slice(2);

function plain(value, depth = 0) {
  // Arrays as their length and first items (two levels deep), typed arrays as their length.
  if (ArrayBuffer.isView(value)) return { length: value.length };
  if (Array.isArray(value)) {
    const first = depth < 2 ? value.slice(0, 3).map((v) => plain(v, depth + 1)) : [];
    return { length: value.length, first };
  }
  if (typeof value === "bigint") return Number(value);
  if (value !== null && typeof value === "object") {
    const out = {};
    for (const [key, inner] of Object.entries(value)) out[key] = plain(inner, depth);
    return out;
  }
  return value;
}

await zstd.isLoaded;
const file = await open(path, "r");
const readable = {
  size: async () => BigInt((await file.stat()).size),
  read: async (offset, size) => {
    const buffer = new Uint8Array(Number(size));
    await file.read(buffer, 0, Number(size), Number(offset));
    return buffer;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data, size) => zstd.decompress(data, Number(size)) },
});
const topics = {};
const readers = new Map();
for (const channel of reader.channelsById.values()) {
  if (!wanted.some((suffix) => channel.topic.endsWith(suffix))) continue;
  const schema = reader.schemasById.get(channel.schemaId);
  const text = new TextDecoder().decode(schema.data);
  const decoder = new MessageReader(parse(text, { ros2: true }));
  readers.set(channel.id, { topic: channel.topic, schema: schema.name, reader: decoder });
}
const names = [...readers.values()].map((r) => r.topic);
for await (const message of reader.readMessages({ topics: names })) {
  const entry = readers.get(message.channelId);
  const decoded = entry.reader.readMessage(message.data);
  const seen = (topics[entry.topic] ??= { schema: entry.schema, count: 0 });
  seen.count += 1;
  seen.last = plain(decoded);
}
await file.close();
process.stdout.write(JSON.stringify(topics) + "\n");
