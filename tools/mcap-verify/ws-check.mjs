#!/usr/bin/env node
// An independent client of `servoamp bridge`: the Foxglove WebSocket
// protocol's reference client (@foxglove/ws-protocol) over `ws`, protobuf
// decoded with protobufjs from the schema the server advertises.
//
//   node tools/mcap-verify/ws-check.mjs URL --seconds S [--param NAME --good V --bad V]
//                                         [--timeout S] [--origin O] [--subprotocol P]
//                                         [--readonly]
//
// 1. subscribes to /servoamp/cycle and /servoamp/param and receives cycles
//    until S seconds of controller time (log time) are covered: counts them,
//    and counts every cycle that is not the previous one + 1;
// 2. with --param: lists the parameters (getParameters), subscribes to NAME's
//    updates, sets NAME to the good value and waits for the change on
//    /servoamp/param and in the parameter values; sets the bad value and
//    waits for the error status, then lists again.
// --readonly: the connection is expected to be read-only (no token in URL):
//    the good value's set must come back as an error status with the value
//    unchanged (and no change on /servoamp/param).
// --frames TOPIC:N: also subscribes to TOPIC (a CAN bus, /servoamp/can0) and
//    waits for N of its messages after the cycles: counts them per CAN id
//    and keeps the first 20 (id, t_bus_ns, log time).
// --origin: the Origin header a browser page of that origin would send.
// Prints one JSON object with what it saw; exit status 0 when it got through
// every step, 1 otherwise (the JSON says where it stopped).
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const { FileDescriptorSet } = require("protobufjs/ext/descriptor");

const argv = process.argv.slice(2);
const url = argv[0];
const opt = (name, def) => {
  const i = argv.indexOf(name);
  return i >= 0 ? argv[i + 1] : def;
};
const seconds = Number(opt("--seconds", "3"));
const timeoutS = Number(opt("--timeout", "120"));
const pname = opt("--param", null);
const SUBPROTOCOL = opt("--subprotocol", "foxglove.sdk.v1");
const good = Number(opt("--good", "NaN"));
const bad = Number(opt("--bad", "NaN"));
const origin = opt("--origin", null);
const readonly = argv.includes("--readonly");
const framesOpt = opt("--frames", null);
const framesTopic = framesOpt ? framesOpt.slice(0, framesOpt.lastIndexOf(":")) : null;
const framesWanted = framesOpt ? Number(framesOpt.slice(framesOpt.lastIndexOf(":") + 1)) : 0;

const out = {
  url,
  step: "connect",
  channels: [],
  cycles: { count: 0, first: null, last: null, out_of_order: 0, first_t: null, last_t: null },
  axes: null,
  param_list: null,
  param_changes: [],
  set_good: null,
  set_bad: null,
  statuses: [],
  list_after: null,
  frames: framesTopic ? { topic: framesTopic, count: 0, by_id: {}, first: [] } : null,
  ok: false,
};

function finish(code) {
  console.log(JSON.stringify(out, (_k, v) => (typeof v === "bigint" ? v.toString() : v)));
  process.exit(code);
}
setTimeout(() => {
  out.error = `timeout after ${timeoutS} s in step ${out.step}`;
  finish(1);
}, timeoutS * 1000);

function pbType(ch) {
  const bytes = Buffer.from(ch.schema, "base64");
  const root = protobuf.Root.fromDescriptor(FileDescriptorSet.decode(bytes));
  root.resolveAll();
  return root.lookupType(ch.schemaName);
}

const client = new FoxgloveClient({
  // foxglove-sdk serves the protocol under the subprotocol name "foxglove.sdk.v1"
  // (the spec of "foxglove.websocket.v1", which this client implements, renamed)
  ws: new WebSocket(url, [SUBPROTOCOL], origin ? { origin } : {}),
});
const subs = new Map(); // subscription id -> { topic, type }
const waiters = []; // { pred, resolve }
function waitFor(pred) {
  return new Promise((resolve) => waiters.push({ pred, resolve }));
}
function emit(ev) {
  for (let i = waiters.length - 1; i >= 0; i--) {
    if (waiters[i].pred(ev)) {
      waiters[i].resolve(ev);
      waiters.splice(i, 1);
    }
  }
}

client.on("error", (e) => {
  out.error = String(e && e.message ? e.message : e);
  finish(1);
});
client.on("close", () => {
  if (!out.ok) {
    out.error = out.error ?? "connection closed";
    finish(1);
  }
});
client.on("advertise", (channels) => {
  for (const ch of channels) {
    out.channels.push({ topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName });
    if (ch.topic === "/servoamp/cycle" || ch.topic === "/servoamp/param" || ch.topic === framesTopic) {
      const id = client.subscribe(ch.id);
      subs.set(id, { topic: ch.topic, type: pbType(ch) });
    }
  }
});
client.on("status", (s) => {
  out.statuses.push({ level: s.level, message: s.message });
  emit({ kind: "status", s });
});
client.on("parameterValues", (pv) => emit({ kind: "params", pv }));
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = subs.get(subscriptionId);
  if (!sub) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  const m = sub.type.toObject(sub.type.decode(bytes), { longs: String, defaults: true });
  if (sub.topic === framesTopic) {
    const f = out.frames;
    f.count++;
    const id = `0x${m.id.toString(16)}`;
    f.by_id[id] = (f.by_id[id] ?? 0) + 1;
    if (f.first.length < 20) f.first.push({ id, t_bus_ns: m.tBusNs, log_time: timestamp, from_servo: m.fromServo });
    if (f.count >= framesWanted) emit({ kind: "frames_done" });
    return;
  }
  if (sub.topic === "/servoamp/param") {
    out.param_changes.push({ name: m.name, value: m.value });
    emit({ kind: "param", m });
    return;
  }
  const c = out.cycles;
  const cyc = BigInt(m.cycle);
  if (c.last !== null && cyc !== BigInt(c.last) + 1n) c.out_of_order++;
  if (c.first === null) {
    c.first = cyc;
    c.first_t = timestamp;
    out.axes = m.axes.length;
  }
  c.last = cyc;
  c.last_t = timestamp;
  c.count++;
  if (timestamp - c.first_t >= BigInt(Math.round(seconds * 1e9))) emit({ kind: "cycles_done" });
});

function valueOf(pv, name) {
  const p = pv.parameters.find((q) => q.name === name);
  return p ? p.value : undefined;
}

// the parameter's value as the server lists it after the sets
async function listAfter() {
  out.step = "list after";
  const ev = waitFor((e) => e.kind === "params" && e.pv.id === "list2");
  client.getParameters([pname], "list2");
  out.list_after = valueOf((await ev).pv, pname);
}

function done() {
  out.step = "done";
  out.ok = true;
  client.close();
  finish(0);
}

(async () => {
  out.step = "cycles";
  await waitFor((e) => e.kind === "cycles_done");
  for (const [id, s] of subs) if (s.topic === "/servoamp/cycle") client.unsubscribe(id);
  if (framesTopic && out.frames.count < framesWanted) {
    out.step = `frames on ${framesTopic}`;
    await waitFor((e) => e.kind === "frames_done");
  }
  if (pname) {
    out.step = "list";
    let ev = waitFor((e) => e.kind === "params" && e.pv.id === "list1");
    client.getParameters([], "list1");
    const list = (await ev).pv;
    out.param_list = list.parameters.map((p) => ({ name: p.name, value: p.value, type: p.type }));
    client.subscribeParameterUpdates([pname]);

    if (readonly) {
      out.step = "set refused (read-only)";
      const before = valueOf(list, pname);
      const refusal = waitFor((e) => e.kind === "status" && e.s.level === 2);
      ev = waitFor((e) => e.kind === "params" && e.pv.id === "set1");
      client.setParameters([{ name: pname, value: good, type: "float64" }], "set1");
      out.set_readonly = { before, status: (await refusal).s.message, reply: valueOf((await ev).pv, pname) };
      await listAfter();
      done();
      return;
    }

    out.step = "set good";
    const change = waitFor((e) => e.kind === "param" && e.m.name === pname && Math.abs(e.m.value - good) < 1e-6);
    const update = waitFor((e) => e.kind === "params" && e.pv.id === undefined && Math.abs(valueOf(e.pv, pname) - good) < 1e-6);
    ev = waitFor((e) => e.kind === "params" && e.pv.id === "set1");
    client.setParameters([{ name: pname, value: good, type: "float64" }], "set1");
    out.set_good = { reply: valueOf((await ev).pv, pname) };
    out.set_good.channel = (await change).m.value;
    out.set_good.update = valueOf((await update).pv, pname);

    out.step = "set bad";
    const refusal = waitFor((e) => e.kind === "status" && e.s.level === 2);
    ev = waitFor((e) => e.kind === "params" && e.pv.id === "set2");
    client.setParameters([{ name: pname, value: bad, type: "float64" }], "set2");
    out.set_bad = { status: (await refusal).s.message, reply: valueOf((await ev).pv, pname) };
    await listAfter();
  }
  done();
})();
