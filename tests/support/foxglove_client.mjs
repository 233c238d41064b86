// An independent Foxglove WebSocket client: `@foxglove/ws-protocol`'s FoxgloveClient over the
// `ws` package, as scripts/node-env.sh installs them. It connects, lists the channels and their
// schemas, subscribes to every channel, decodes what comes (JSON channels parsed; a raw layout's
// header tick read at the offset its own schema gives), asks for the parameters, the connection
// graph and `/mole/status`, and prints one JSON object of what it saw.
//
// Usage: node foxglove_client.mjs ENV_DIR URL [--run] [--until NS] [--timeout S] [--set NAME=VALUE]
//   --run       publish a malformed message, then {"pace":"run"} on /operator (client publishing)
//   --until NS  stop once a /truth message at log time >= NS came
//   --set N=V   set the parameter N to the number V once subscribed
//   --quiet     keep no messages (only the counts and the pace) and ask nothing: for a long run
//   --play X    (a recording) play at X times the recorded speed, from --seek NS if given; the
//               protocol's playback control request, which this client package does not send
//               itself, written on its socket by hand
// With ENV_DIR alone and --versions it prints the packages' versions (a check that they load).
import { createRequire } from "node:module";
import path from "node:path";

const [envDir, url, ...rest] = process.argv.slice(2);
const require = createRequire(path.resolve(envDir, "package.json"));
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
if (url === "--versions") {
  const version = (p) => require(`${p}/package.json`).version;
  console.log(`@foxglove/ws-protocol ${version("@foxglove/ws-protocol")}, ws ${version("ws")}`);
  process.exit(0);
}
const flag = (name) => rest.includes(name);
const value = (name, fallback) => {
  const i = rest.indexOf(name);
  return i >= 0 ? rest[i + 1] : fallback;
};
const until = BigInt(value("--until", "18446744073709551615"));
const timeoutS = Number(value("--timeout", "60"));
const set = value("--set", undefined);
const quiet = flag("--quiet");

const seen = {
  serverInfo: null,
  channels: [],
  messages: {},
  rawTicks: {},
  rawTruth: [],
  parameters: null,
  setParameters: null,
  graph: null,
  services: [],
  // When the truths after step 0 came (ms of this process's clock) and their log times: the
  // run's pace as a client sees it (scripts/foxglove-cost.sh).
  paced: null,
  status: null,
  errors: [],
  counts: {},
};
const channels = new Map(); // by subscription id
const headerTick = new Map();
const decoder = new TextDecoder();

// Where a raw layout's header keeps its tick, from the channel's own schema (mole-layout JSON).
function tickOffset(schema) {
  const layout = JSON.parse(schema);
  const header = layout.fields.find((f) => f.name === "header");
  const tick = layout.structs[header.type].fields.find((f) => f.name === "tick");
  return header.offset + tick.offset;
}

const ws = new WebSocket(url, ["foxglove.sdk.v1"]);
const client = new FoxgloveClient({ ws });
let finished = false;
// Replies still awaited (parameters, a service call): the end waits for them (up to --timeout).
const pending = new Set();
function finishWhenAnswered() {
  if (pending.size === 0) finish();
  else setTimeout(finishWhenAnswered, 100);
}
function finish() {
  if (finished) return;
  finished = true;
  client.close();
  // Exit once all of it went down the pipe (process.exit alone cuts it at 64 KiB).
  const text = JSON.stringify(seen, (_, v) => (typeof v === "bigint" ? v.toString() : v));
  process.stdout.write(text + "\n", () => process.exit(0));
}
setTimeout(() => {
  seen.errors.push(`timeout after ${timeoutS} s`);
  finish();
}, timeoutS * 1000);

client.on("error", (e) => seen.errors.push(String(e)));
client.on("serverInfo", (info) => {
  seen.serverInfo = { name: info.name, capabilities: info.capabilities };
});
let subscribed = false;
client.on("advertise", (advertised) => {
  for (const c of advertised) {
    seen.channels.push({
      topic: c.topic,
      encoding: c.encoding,
      schemaName: c.schemaName,
      schemaEncoding: c.schemaEncoding,
    });
    const subscription = client.subscribe(c.id);
    channels.set(subscription, c);
    if (c.encoding === "mole-layout") headerTick.set(subscription, tickOffset(c.schema));
  }
  if (subscribed) return;
  subscribed = true;
  const caps = seen.serverInfo?.capabilities ?? [];
  if (caps.includes("connectionGraph")) client.subscribeConnectionGraph();
  if (caps.includes("parameters") && !quiet) {
    pending.add("all");
    client.getParameters([], "all");
  }
  if (set && caps.includes("parameters")) {
    pending.add("set");
    const [name, v] = set.split("=");
    client.setParameters([{ name, value: Number(v) }], "set");
  }
  const play = value("--play", undefined);
  if (play && caps.includes("playbackControl")) {
    const seek = value("--seek", undefined);
    const id = new TextEncoder().encode("play");
    const request = new DataView(new ArrayBuffer(1 + 1 + 4 + 1 + 8 + 4 + id.length));
    request.setUint8(0, 3); // op: playback control request
    request.setUint8(1, 0); // play
    request.setFloat32(2, Number(play), true);
    request.setUint8(6, seek === undefined ? 0 : 1);
    request.setBigUint64(7, BigInt(seek ?? 0), true);
    request.setUint32(15, id.length, true);
    new Uint8Array(request.buffer).set(id, 19);
    setTimeout(() => ws.send(request.buffer), 300);
  }
  if (flag("--run")) {
    const operator = client.advertise({ topic: "/operator", encoding: "json", schemaName: "mole.Operator" });
    const send = (text) => client.sendMessage(operator, new TextEncoder().encode(text));
    // Refused and counted by the server, which goes on.
    send("this is not JSON");
    setTimeout(() => send(JSON.stringify({ pace: "run" })), 200);
  }
});
client.on("advertiseServices", (services) => {
  for (const s of services) {
    seen.services.push(s.name);
    if (s.name === "/mole/status" && !quiet) {
      pending.add("status");
      client.sendServiceCallRequest({ serviceId: s.id, callId: 1, encoding: "json", data: new TextEncoder().encode("{}") });
    }
  }
});
client.on("serviceCallResponse", (r) => {
  seen.status = JSON.parse(decoder.decode(r.data));
  pending.delete("status");
});
client.on("serviceCallFailure", (f) => {
  seen.errors.push(`service: ${f.message}`);
  pending.delete("status");
});
client.on("parameterValues", (p) => {
  if (p.id === "all") seen.parameters = p.parameters;
  if (p.id === "set") seen.setParameters = p.parameters;
  pending.delete(p.id);
});
client.on("connectionGraphUpdate", (g) => {
  seen.graph = { publishedTopics: g.publishedTopics, subscribedTopics: g.subscribedTopics, advertisedServices: g.advertisedServices };
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = channels.get(subscriptionId);
  if (!channel) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  seen.counts[channel.topic] = (seen.counts[channel.topic] ?? 0) + 1;
  if (channel.encoding === "json") {
    const message = JSON.parse(decoder.decode(bytes));
    if (!quiet) (seen.messages[channel.topic] ??= []).push({ logTime: timestamp, message });
    if (channel.topic === "/truth" && timestamp > 0n) {
      const now = performance.now();
      seen.paced ??= { firstMs: now, firstLogTime: timestamp };
      Object.assign(seen.paced, { lastMs: now, lastLogTime: timestamp });
    }
    if (channel.topic === "/truth" && timestamp >= until) setTimeout(finishWhenAnswered, 300);
    return;
  }
  if (quiet) return;
  const offset = headerTick.get(subscriptionId);
  const tick = data.getBigUint64(offset, true);
  (seen.rawTicks[channel.topic] ??= []).push(tick);
  if (channel.topic === "/mole/world/truth") {
    seen.rawTruth.push({ logTime: timestamp, tick, base64: Buffer.from(bytes).toString("base64") });
  }
});
