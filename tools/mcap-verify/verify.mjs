#!/usr/bin/env node
// Reads a servoamp MCAP recording with the TypeScript MCAP implementation
// (@mcap/core, decompression from @mcap/support) and prints one JSON object:
// what it found, independently of the Python writer and reader.
//
//   node tools/mcap-verify/verify.mjs FILE.mcap            indexed read (finalized file)
//   node tools/mcap-verify/verify.mjs --stream FILE.mcap   record-by-record (e.g. truncated)
//
// Exit status 0 when the file was read (JSON says what was found), 1 on error.
// JSON messages are parsed as JSON; protobuf messages (servoamp bridge) are
// decoded with protobufjs from the FileDescriptorSet in the file's schema
// record (as Foxglove does); undecodable messages count as json_errors /
// decode_errors.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { open, readFile } from "node:fs/promises";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const protobuf = require("protobufjs");
const { FileDescriptorSet } = require("protobufjs/ext/descriptor");

const args = process.argv.slice(2);
const stream = args[0] === "--stream";
const file = stream ? args[1] : args[0];
if (!file) {
  console.error("usage: verify.mjs [--stream] FILE.mcap");
  process.exit(2);
}

const out = {
  mode: stream ? "stream" : "indexed",
  library: null,
  profile: null,
  messages: 0,
  by_topic: {},
  schemas: {},
  encodings: {},
  json_errors: 0,
  decode_errors: 0,
  log_time_min: null,
  log_time_max: null,
  cycles: { count: 0, first: null, last: null, non_increasing: 0 },
  chunks: null,
  compression: [],
  statistics_message_count: null,
  complete: false,
  error: null,
};

const pbTypes = new Map(); // schema id -> protobufjs Type
function pbType(schema) {
  let t = pbTypes.get(schema.id);
  if (!t) {
    const root = protobuf.Root.fromDescriptor(FileDescriptorSet.decode(schema.data));
    root.resolveAll();
    t = root.lookupType(schema.name);
    pbTypes.set(schema.id, t);
  }
  return t;
}

function onMessage(channel, schemaName, msg, schema) {
  const topic = channel.topic;
  out.messages++;
  out.by_topic[topic] = (out.by_topic[topic] ?? 0) + 1;
  out.schemas[topic] = schemaName;
  out.encodings[topic] = channel.messageEncoding;
  const t = msg.logTime.toString();
  if (out.log_time_min === null || BigInt(t) < BigInt(out.log_time_min)) out.log_time_min = t;
  if (out.log_time_max === null || BigInt(t) > BigInt(out.log_time_max)) out.log_time_max = t;
  let obj;
  if (channel.messageEncoding === "protobuf") {
    try {
      obj = pbType(schema).toObject(pbType(schema).decode(msg.data), { longs: Number, defaults: true });
    } catch {
      out.decode_errors++;
      return;
    }
  } else {
    try {
      obj = JSON.parse(new TextDecoder().decode(msg.data));
    } catch {
      out.json_errors++;
      return;
    }
  }
  if (topic === "/servoamp/cycle") {
    const c = out.cycles;
    if (c.last !== null && obj.cycle <= c.last) c.non_increasing++;
    if (c.first === null) c.first = obj.cycle;
    c.last = obj.cycle;
    c.count++;
  }
}

const decompressHandlers = await loadDecompressHandlers();
try {
  if (!stream) {
    const fh = await open(file, "r");
    const size = BigInt((await fh.stat()).size);
    const readable = {
      size: async () => size,
      read: async (offset, length) => {
        const buf = new Uint8Array(Number(length));
        await fh.read(buf, 0, Number(length), Number(offset));
        return buf;
      },
    };
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    out.library = reader.header.library;
    out.profile = reader.header.profile;
    out.chunks = reader.chunkIndexes.length;
    out.compression = [...new Set(reader.chunkIndexes.map((c) => c.compression))];
    out.statistics_message_count = reader.statistics ? Number(reader.statistics.messageCount) : null;
    for await (const msg of reader.readMessages()) {
      const ch = reader.channelsById.get(msg.channelId);
      const sc = reader.schemasById.get(ch.schemaId);
      onMessage(ch, sc ? sc.name : null, msg, sc);
    }
    out.complete = true;
    await fh.close();
  } else {
    const data = await readFile(file);
    const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
    reader.append(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    const channels = new Map();
    const schemas = new Map();
    let chunks = 0;
    try {
      for (let rec; (rec = reader.nextRecord()); ) {
        if (rec.type === "Header") {
          out.library = rec.library;
          out.profile = rec.profile;
        } else if (rec.type === "Schema") schemas.set(rec.id, rec);
        else if (rec.type === "Channel") channels.set(rec.id, rec);
        else if (rec.type === "Message") {
          const ch = channels.get(rec.channelId);
          const sc = schemas.get(ch.schemaId);
          onMessage(ch, sc ? sc.name : null, rec, sc);
        } else if (rec.type === "ChunkIndex") chunks++;
        else if (rec.type === "Footer") out.complete = true;
      }
    } catch (e) {
      out.error = String(e && e.message ? e.message : e); // truncated tail
    }
    out.chunks = chunks;
  }
} catch (e) {
  out.error = String(e && e.message ? e.message : e);
  console.log(JSON.stringify(out));
  process.exit(1);
}
console.log(JSON.stringify(out));
