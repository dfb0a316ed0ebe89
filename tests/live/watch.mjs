// Watches a bench run's live view with Foxglove's own WebSocket protocol client
// (@foxglove/ws-protocol), as Foxglove's app would: subscribes to every channel it advertises,
// decodes each message by its advertised schema (JSON, validated against the JSON schema with
// Ajv) and writes what it saw as JSON when the server closes the connection.
//
//   node watch.mjs ws://HOST:PORT OUT.json [--pause-at S --pause-for MS] [--seek-at S --seek-to T]
//                  [--until-result] [--deadline S]
//
// --pause-at S: once the server's time passes S seconds, ask for a pause (the protocol's
// playback control request, binary op 3, as Foxglove's app sends it), wait MS milliseconds of
// wall time, then ask to play again. --seek-at S --seek-to T: once the server's time passes S
// seconds, ask to play from T seconds (a seek, as Foxglove's timeline sends it).
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";
import Ajv2020 from "ajv/dist/2020.js";

const { FoxgloveClient } = wsProtocol;
import { writeFileSync } from "node:fs";

const [url, out, ...rest] = process.argv.slice(2);
if (!url || !out) {
  console.error("usage: node watch.mjs ws://HOST:PORT OUT.json [--pause-at S --pause-for MS] [--deadline S]");
  process.exit(2);
}
const opt = (name, dflt) => {
  const i = rest.indexOf(name);
  return i >= 0 ? Number(rest[i + 1]) : dflt;
};
const pauseAt = opt("--pause-at", NaN);
const pauseForMs = opt("--pause-for", 3000);
const seekAt = opt("--seek-at", NaN);
const seekTo = opt("--seek-to", 0);
// --until-result: close once the run's result has come (a replay's server stays up for seeks
// while a viewer is connected)
const untilResult = rest.includes("--until-result");
const deadline = Date.now() + opt("--deadline", 900) * 1000;

const ajv = new Ajv2020({ strict: false, allErrors: false, validateFormats: false });
const seen = {
  url,
  serverInfo: null,
  channels: {},
  messages: {},
  invalid: [],
  times: 0,
  timeDecreases: 0,
  firstTime: null,
  lastTime: null,
  dwells: [],
  commands: [],
  lastNavLocation: null,
  firstNavLocation: null,
  navLocations: 0,
  result: null,
  headings: [],
  northFindingResult: null,
  hilLog: [],
  navLog: 0,
  truthTurntable: 0,
  maxTableAngle: null,
  playbackStates: [],
  paused: null,
  seek: null,
  resumed: null,
  connectAttempts: 0,
  errors: [],
};
const schemas = new Map(); // channel id -> { topic, validate }
const subs = new Map(); // subscription id -> channel id
const decoder = new TextDecoder();

function finish(code) {
  writeFileSync(out, JSON.stringify(seen, null, 1));
  process.exit(code);
}

function timeNs(t) {
  return BigInt(t);
}

function onMessage({ subscriptionId, timestamp, data }) {
  const chId = subs.get(subscriptionId);
  const ch = schemas.get(chId);
  if (!ch) {
    seen.invalid.push({ subscriptionId, why: "unknown subscription" });
    return;
  }
  seen.messages[ch.topic] = (seen.messages[ch.topic] ?? 0) + 1;
  let m;
  try {
    m = JSON.parse(decoder.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)));
  } catch (e) {
    seen.invalid.push({ topic: ch.topic, why: `not JSON: ${e}` });
    return;
  }
  if (!ch.validate(m)) {
    if (seen.invalid.length < 20) {
      seen.invalid.push({ topic: ch.topic, why: ajv.errorsText(ch.validate.errors), message: m });
    }
    return;
  }
  switch (ch.topic) {
    case "/turntable/dwell":
      seen.dwells.push(m);
      break;
    case "/turntable/command":
      seen.commands.push(m);
      break;
    case "/nav/location":
      seen.navLocations += 1;
      seen.firstNavLocation ??= { ...m, publish_ns: timestamp.toString() };
      seen.lastNavLocation = { ...m, publish_ns: timestamp.toString() };
      break;
    case "/nav/event":
      if (m.kind === "north_finding_progress" && m.progress?.heading_deg != null) {
        seen.headings.push(m.progress.heading_deg);
      }
      if (m.kind === "north_finding_result") seen.northFindingResult = m.result;
      break;
    case "/hil/result":
      seen.result = m;
      if (untilResult) setTimeout(() => finish(0), 500);
      break;
    case "/hil/log":
      seen.hilLog.push(m.message);
      break;
    case "/nav/log":
      seen.navLog += 1;
      break;
    case "/truth/turntable":
      seen.truthTurntable += 1;
      break;
  }
}

let pauseState = "none";
let seekState = "none";
function onTime({ timestamp }, ws) {
  const t = timeNs(timestamp);
  seen.times += 1;
  if (seen.lastTime !== null && t < BigInt(seen.lastTime)) seen.timeDecreases += 1;
  seen.firstTime ??= t.toString();
  seen.lastTime = t.toString();
  if (!Number.isNaN(seekAt) && seekState === "none" && t >= BigInt(Math.round(seekAt * 1e9))) {
    seekState = "asked";
    seen.seek = { at_ns: t.toString(), to_ns: String(Math.round(seekTo * 1e9)) };
    ws.send(playbackRequest(0, "seek-1", BigInt(Math.round(seekTo * 1e9))));
  }
  if (!Number.isNaN(pauseAt) && pauseState === "none" && t >= BigInt(Math.round(pauseAt * 1e9))) {
    pauseState = "paused";
    seen.paused = { at_ns: t.toString(), wall: Date.now() };
    ws.send(playbackRequest(1, "pause-1"));
    setTimeout(() => {
      pauseState = "resumed";
      seen.resumed = { wall: Date.now(), lastTimeWhilePaused: seen.lastTime };
      ws.send(playbackRequest(0, "play-1"));
    }, pauseForMs);
  }
}

// The protocol's playback control request (client binary op 3): command (0 play, 1 pause),
// speed f32, had_seek u8, seek time u64, request id (u32 length, UTF-8).
function playbackRequest(command, id, seekNs) {
  const idBytes = new TextEncoder().encode(id);
  const b = Buffer.alloc(1 + 1 + 4 + 1 + 8 + 4 + idBytes.length);
  let o = 0;
  b.writeUInt8(3, o++);
  b.writeUInt8(command, o++);
  b.writeFloatLE(1.0, o); o += 4;
  b.writeUInt8(seekNs === undefined ? 0 : 1, o++);
  b.writeBigUInt64LE(seekNs ?? 0n, o); o += 8;
  b.writeUInt32LE(idBytes.length, o); o += 4;
  Buffer.from(idBytes).copy(b, o);
  return b;
}

function connect() {
  seen.connectAttempts += 1;
  const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  const client = new FoxgloveClient({ ws });
  let opened = false;
  client.on("open", () => {
    opened = true;
  });
  client.on("serverInfo", (info) => {
    seen.serverInfo = info;
  });
  client.on("advertise", (channels) => {
    for (const c of channels) {
      let validate;
      try {
        if (c.encoding !== "json" || c.schemaEncoding !== "jsonschema") throw new Error(`encoding ${c.encoding}/${c.schemaEncoding}`);
        const s = JSON.parse(c.schema);
        delete s.$schema;
        delete s.$id;
        validate = ajv.compile(s);
      } catch (e) {
        seen.invalid.push({ topic: c.topic, why: `schema: ${e}` });
        validate = () => false;
      }
      schemas.set(c.id, { topic: c.topic, validate });
      seen.channels[c.topic] = { schemaName: c.schemaName, encoding: c.encoding };
      subs.set(client.subscribe(c.id), c.id);
    }
  });
  client.on("message", onMessage);
  client.on("time", (t) => onTime(t, ws));
  ws.on("message", (data, isBinary) => {
    // the playback state (server op 5), which this version of the client does not parse
    const b = Buffer.from(data);
    if (isBinary && b[0] === 5 && b.length >= 18) {
      seen.playbackStates.push({ status: b[1], time_ns: b.readBigUInt64LE(2).toString() });
    }
  });
  client.on("error", (e) => {
    if (opened && !String(e).includes("binary message: 5") && seen.errors.length < 10) seen.errors.push(String(e));
  });
  client.on("close", () => {
    if (!opened) {
      if (Date.now() > deadline) {
        seen.errors.push("could not connect before the deadline");
        finish(1);
      }
      setTimeout(connect, 500);
      return;
    }
    finish(0);
  });
}

setTimeout(() => {
  seen.errors.push("deadline reached while connected");
  finish(1);
}, Math.max(0, deadline - Date.now())).unref();
connect();
