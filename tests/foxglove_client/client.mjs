// A Foxglove WebSocket client built from Foxglove's own libraries, as the Foxglove app is:
// connects to `./camo view`, lists the channels, subscribes to the topics named, decodes each
// message with the channel's ros2msg schema, and prints one JSON object.
//   node client.mjs ws://127.0.0.1:8765 TIMEOUT_S TOPIC_SUFFIX...
import wsProtocol from "@foxglove/ws-protocol";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

// CommonJS packages: their exports come as one default object.
const { FoxgloveClient } = wsProtocol;
const { parse } = rosmsg;
const { MessageReader } = serialization;

const [url, timeout, ...wanted] = process.argv.slice(2);
// The Foxglove SDK's server speaks foxglove.sdk.v1; ws-protocol 0.8 offers foxglove.websocket.v1.
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // id -> channel
const readers = new Map(); // subscription id -> { topic, reader }
const decoded = {};
const errors = [];

// Fields as they decode: arrays by their length (and an array of messages, such as a tile's
// votes, by its first one too), nested messages as "object".
function summary(message) {
  const out = {};
  for (const [key, value] of Object.entries(message)) {
    if (Array.isArray(value) && value.length && typeof value[0] === "object" && !ArrayBuffer.isView(value[0]))
      out[key] = { length: value.length, first: summary(value[0]) };
    else if (ArrayBuffer.isView(value) || Array.isArray(value)) out[key] = { length: value.length };
    else if (value !== null && typeof value === "object") out[key] = "object";
    else out[key] = value;
  }
  return out;
}

function finish(code) {
  const topics = [...channels.values()].map((c) => ({
    topic: c.topic,
    encoding: c.encoding,
    schemaName: c.schemaName,
    schemaEncoding: c.schemaEncoding,
  }));
  // uint64 fields (RobotStatus.known_slots) decode as BigInt, which JSON has no form for.
  const plain = (_key, value) => (typeof value === "bigint" ? value.toString() : value);
  process.stdout.write(JSON.stringify({ channels: topics, decoded, errors }, plain) + "\n");
  client.close();
  process.exit(code);
}

client.on("error", (error) => {
  errors.push(String(error?.message ?? error));
});
function subscribe(channel) {
  try {
    const reader = new MessageReader(parse(channel.schema, { ros2: true }));
    readers.set(client.subscribe(channel.id), { topic: channel.topic, reader, channel: channel.id });
  } catch (error) {
    errors.push(`${channel.topic}: schema: ${error.message}`);
  }
}

client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    channels.set(channel.id, channel);
    if (wanted.some((suffix) => channel.topic.endsWith(suffix))) subscribe(channel);
  }
});
client.on("unadvertise", (ids) => {
  for (const id of ids) channels.delete(id);
});
// The Foxglove SDK's server (0.30) sends an advertisement before it records the channel as
// advertised to this client, so a subscription that answers at once can meet "Unknown channel
// ID" on a loaded machine: subscribe again while the channel is still advertised, as a user
// would click the topic again.
client.on("status", ({ level, message }) => {
  const unknown = /^Unknown channel ID: (\d+)$/.exec(message);
  if (!unknown) return;
  const id = Number(unknown[1]);
  for (const [subscription, entry] of readers)
    if (entry.channel === id) {
      readers.delete(subscription);
      client.unsubscribe(subscription);
    }
  setTimeout(() => channels.has(id) && subscribe(channels.get(id)), 100);
});
client.on("message", ({ subscriptionId, data }) => {
  const entry = readers.get(subscriptionId);
  if (!entry || decoded[entry.topic]) return;
  try {
    decoded[entry.topic] = summary(entry.reader.readMessage(data));
  } catch (error) {
    errors.push(`${entry.topic}: ${error.message}`);
  }
  const topics = Object.keys(decoded);
  if (wanted.every((suffix) => topics.some((topic) => topic.endsWith(suffix)))) finish(0);
});
setTimeout(() => finish(1), Number(timeout) * 1000);
