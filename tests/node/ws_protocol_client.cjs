// The official Foxglove WebSocket client (@foxglove/ws-protocol) against `evopose view` (tests/test_view.py).
//
// Usage: node ws_protocol_client.cjs URL TOPIC,TOPIC,... TIMEOUT_S
// Connects offering only the client's default subprotocol (FoxgloveClient.SUPPORTED_SUBPROTOCOL), subscribes to every
// channel as it is advertised, decodes messages with each channel's own schema (protobuf: the FileDescriptorSet it
// carries, with protobufjs; json: JSON.parse) and prints one JSON line per event: "open" (the agreed subprotocol),
// "decoded" (once per topic: its schema name, encoding and the decoded message), "done" once every wanted topic was
// decoded (exit 0), or "timeout" (exit 1).
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const [url, wantedArg, timeoutArg] = process.argv.slice(2);
const wanted = new Set(wantedArg.split(","));
const UNKNOWN_CHANNEL = "Unknown channel ID: ";

function emit(record) {
  process.stdout.write(JSON.stringify(record, (_, v) => (typeof v === "bigint" ? Number(v) : v)) + "\n");
}

function decoderOf(channel) {
  if (channel.encoding === "json") {
    const text = new TextDecoder();
    return (bytes) => JSON.parse(text.decode(bytes));
  }
  if (channel.encoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
    return (bytes) => type.toObject(type.decode(bytes), { longs: Number, bytes: String, defaults: false });
  }
  throw new Error(`no decoder for ${channel.topic}: encoding ${channel.encoding}`);
}

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> { channel, decode }
const subscriptions = new Map(); // subscription id -> channel id
const decoded = new Set();

client.on("open", () => emit({ event: "open", subprotocol: ws.protocol }));
client.on("serverInfo", (info) => emit({ event: "serverInfo", name: info.name }));
client.on("error", (error) => emit({ event: "error", message: String(error) }));
client.on("advertise", (list) => {
  for (const channel of list) {
    channels.set(channel.id, { channel, decode: decoderOf(channel) });
    subscriptions.set(client.subscribe(channel.id), channel.id);
  }
});
client.on("status", (status) => {
  // foxglove-sdk advertises a channel a moment before it accepts subscriptions to it: subscribe again
  if (status.message.startsWith(UNKNOWN_CHANNEL)) {
    const channelId = Number(status.message.slice(UNKNOWN_CHANNEL.length));
    setTimeout(() => subscriptions.set(client.subscribe(channelId), channelId), 50);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const { channel, decode } = channels.get(subscriptions.get(subscriptionId));
  if (decoded.has(channel.topic)) {
    return;
  }
  const message = decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
  decoded.add(channel.topic);
  emit({ event: "decoded", topic: channel.topic, schemaName: channel.schemaName, encoding: channel.encoding,
         message });
  if ([...wanted].every((topic) => decoded.has(topic))) {
    emit({ event: "done", decoded: [...decoded] });
    client.close();
    process.exit(0);
  }
});

setTimeout(() => {
  emit({ event: "timeout", decoded: [...decoded], advertised: [...channels.values()].map((c) => c.channel.topic) });
  process.exit(1);
}, Number(timeoutArg) * 1000);
