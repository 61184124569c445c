#!/usr/bin/env node
// A real Foxglove client against simbridge's Foxglove port: @foxglove/ws-protocol's FoxgloveClient
// on a `ws` WebSocket opened with the SDK's subprotocol, messages decoded and encoded by
// @foxglove/rosmsg2-serialization from the schemas the server advertises.
//
//   node foxglove.mjs --url ws://127.0.0.1:PORT --args JSON [--timeout-ms N]
//
// Several checks in one connection (one Node start for the whole path). args:
//   robot        namespace of the robot driven ("" : /cmd_vel, /odom)
//   refuse       {topic, type}: a client channel the server must refuse (a status comes back)
//   rosbridge    a rosbridge URL: roslib 2.1.0 sets a parameter there, seen here as an update
//   params       true: read, set and subscribe robot.max_linear_velocity
//   reset        true: call /reset (and read its line on /rosout, subscribed from the start)
//   time         true: wait for the server's time messages (use_sim_time)
//   graph        true: subscribe to the connection graph (after driving: this client publishes)
//   flood        N: advertise N client channels more (the server refuses past its budget)
//   closed       true: only wait for the server to close the connection (a connection past
//                foxglove_max_clients): {code, reason, serverInfo}
// stdout: one line, {"ok":true,"result":{...}} or {"ok":false,"error":"..."} (as run.mjs).

import { parseArgs } from 'node:util';
import WebSocket from 'ws';
import wsProtocol from '@foxglove/ws-protocol';
import { parse } from '@foxglove/rosmsg';
import rosmsg2 from '@foxglove/rosmsg2-serialization';

const { FoxgloveClient } = wsProtocol;
const { MessageReader, MessageWriter } = rosmsg2;

const log = (...a) => console.error(...a);
console.log = log;

const { values: opts } = parseArgs({
  options: {
    url: { type: 'string' },
    args: { type: 'string', default: '{}' },
    'timeout-ms': { type: 'string', default: '20000' },
  },
});
const args = JSON.parse(opts.args);
const deadline = Date.now() + Number(opts['timeout-ms']);

function finish(ok, payload) {
  process.stdout.write(JSON.stringify(ok ? { ok, result: payload } : { ok, error: payload }) + '\n');
  process.exit(ok ? 0 : 1);
}
setTimeout(() => finish(false, 'timeout'), Number(opts['timeout-ms'])).unref();

/** Resolve when `test()` is true (checked on every event and every 20 ms), or reject. */
function until(what, test, ms = 8000) {
  return new Promise((resolve, reject) => {
    const end = Math.min(Date.now() + ms, deadline);
    const look = () => {
      const v = test();
      if (v) return resolve(v);
      if (Date.now() > end) return reject(new Error(`timed out waiting for ${what}`));
      setTimeout(look, 20);
    };
    look();
  });
}

const ws = new WebSocket(opts.url, ['foxglove.sdk.v1']);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // topic -> channel
const readers = new Map(); // channel id -> reader
const messages = new Map(); // topic -> [{msg, at}]
const services = new Map(); // name -> service
const statuses = [];
const paramValues = []; // every parameterValues event
const times = [];
const responses = new Map(); // call id -> {response|failure}
let serverInfo = null;

client.on('error', (e) => log('error', e));
client.on('serverInfo', (info) => (serverInfo = info));
client.on('status', (s) => statuses.push(s));
client.on('time', (t) => times.push(Number(t.timestamp)));
client.on('advertise', (list) => {
  for (const ch of list) {
    channels.set(ch.topic, ch);
    if (ch.encoding === 'cdr' && ch.schemaEncoding === 'ros2msg') {
      readers.set(ch.id, new MessageReader(parse(ch.schema, { ros2: true })));
    }
  }
});
client.on('advertiseServices', (list) => list.forEach((s) => services.set(s.name, s)));
client.on('message', ({ subscriptionId, data }) => {
  const topic = subs.get(subscriptionId);
  const ch = channels.get(topic);
  const msg = readers.get(ch.id).readMessage(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
  if (!messages.has(topic)) messages.set(topic, []);
  messages.get(topic).push({ msg, at: Date.now() });
});
client.on('parameterValues', (ev) => paramValues.push(ev));
client.on('serviceCallResponse', (r) => responses.set(r.callId, { response: r }));
client.on('serviceCallFailure', (f) => responses.set(f.callId, { failure: f.message }));
const graph = { published: new Map(), subscribed: new Map(), services: new Map() };
client.on('connectionGraphUpdate', (u) => {
  for (const t of u.publishedTopics) graph.published.set(t.name, t.publisherIds);
  for (const t of u.subscribedTopics) graph.subscribed.set(t.name, t.subscriberIds);
  for (const sv of u.advertisedServices) graph.services.set(sv.name, sv.providerIds);
  for (const n of u.removedTopics) { graph.published.delete(n); graph.subscribed.delete(n); }
  for (const n of u.removedServices) graph.services.delete(n);
});

const subs = new Map(); // subscription id -> topic
function subscribe(topic) {
  const ch = channels.get(topic);
  if (!ch) throw new Error(`no channel ${topic}; channels: ${[...channels.keys()].join(' ')}`);
  subs.set(client.subscribe(ch.id), topic);
}

let nextCall = 1;
async function call(name, request = {}) {
  const svc = services.get(name);
  if (!svc) throw new Error(`no service ${name}`);
  const schema = svc.request?.schema ?? svc.requestSchema;
  const writer = new MessageWriter(parse(schema, { ros2: true }));
  const callId = nextCall++;
  client.sendServiceCallRequest({ serviceId: svc.id, callId, encoding: 'cdr', data: new DataView(writer.writeMessage(request).buffer) });
  const got = await until(`the answer of ${name}`, () => responses.get(callId));
  if (got.failure) throw new Error(`${name} failed: ${got.failure}`);
  return got.response;
}

function paramValue(name, value) {
  return paramValues.find((ev) => ev.parameters.some((p) => p.name === name && Math.abs(p.value - value) < 1e-9));
}

async function main() {
  if (args.closed) {
    const [code, reason] = await new Promise((resolve) => ws.once('close', (c, r) => resolve([c, String(r)])));
    return { code, reason, serverInfo: serverInfo !== null };
  }
  await until('serverInfo', () => serverInfo);
  const ns = args.robot ? `/${args.robot}` : '';
  await until('the channels', () => channels.has(`${ns}/odom`) && channels.has(`${ns}/scan`) && channels.has('/tf_static') && channels.has('/rosout'));
  const result = {
    capabilities: serverInfo.capabilities,
    encodings: serverInfo.supportedEncodings ?? [],
    odomSchema: channels.get(`${ns}/odom`).schemaName,
    schemaEncoding: channels.get(`${ns}/odom`).schemaEncoding,
    channelCount: channels.size,
  };
  // /tf_static was published at start: it reaches this late subscriber all the same
  for (const t of [`${ns}/odom`, `${ns}/scan`, '/tf_static', '/rosout']) subscribe(t);
  await until('/tf_static', () => messages.get('/tf_static')?.length);
  result.tfStatic = messages.get('/tf_static')[0].msg.transforms.map((t) => `${t.header.frame_id}->${t.child_frame_id}`);
  await until('1 s of /odom', () => {
    const m = messages.get(`${ns}/odom`) ?? [];
    return m.length > 2 && m[m.length - 1].at - m[0].at >= 1000;
  });
  const odom = messages.get(`${ns}/odom`);
  result.odomRate = (odom.length - 1) / ((odom[odom.length - 1].at - odom[0].at) / 1000);
  result.odomFrames = [odom[0].msg.header.frame_id, odom[0].msg.child_frame_id];
  await until('/scan', () => messages.get(`${ns}/scan`)?.length);
  result.scanRanges = messages.get(`${ns}/scan`)[0].msg.ranges.length;

  // drive: the teleop panel's path (a client channel, CDR of geometry_msgs/msg/Twist)
  const twistDef = parse('geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n' + '='.repeat(80) + '\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n', { ros2: true });
  const twist = new MessageWriter(twistDef);
  const cmd = client.advertise({ topic: `${ns}/cmd_vel`, encoding: 'cdr', schemaName: 'geometry_msgs/msg/Twist' });
  const x0 = odom[odom.length - 1].msg.pose.pose.position.x;
  const drive = setInterval(() => client.sendMessage(cmd, twist.writeMessage({ linear: { x: 0.3, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } })), 100);
  await until('the robot to move', () => odom[odom.length - 1].msg.pose.pose.position.x > x0 + 0.05);
  clearInterval(drive);
  result.moved = odom[odom.length - 1].msg.pose.pose.position.x - x0;

  if (args.refuse) {
    const before = statuses.length;
    const bad = client.advertise({ topic: args.refuse.topic, encoding: 'cdr', schemaName: args.refuse.type });
    client.sendMessage(bad, twist.writeMessage({ linear: { x: 0.3, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } }));
    await until('a status for the refused publish', () => statuses.length > before);
    result.refusal = statuses.slice(before).map((s) => s.message);
  }
  if (args.flood) {
    const before = statuses.length;
    for (let k = 0; k < args.flood; k++) client.advertise({ topic: `${ns}/flood_${k}`, encoding: 'cdr', schemaName: 'std_msgs/msg/String' });
    await until('the refusal of a channel too many', () => statuses.slice(before).some((s) => s.message.includes('too many client channels')));
    result.flood = statuses.slice(before).map((s) => s.message);
  }
  if (args.reset) {
    await call('/reset');
    result.reset = true;
    const line = await until('the reset on /rosout', () => (messages.get('/rosout') ?? []).find((m) => m.msg.msg.startsWith('world reset')));
    result.rosout = { msg: line.msg.msg, level: line.msg.level, name: line.msg.name };
  }
  result.services = [...services.keys()].filter((n) => ['/reset', '/spawn', '/kill', '/estop', '/estop/reset'].includes(n));
  if (args.params) {
    const name = '/virtual_robot.robot.max_linear_velocity';
    client.getParameters([name], 'get1');
    const got = await until('getParameters', () => paramValues.find((ev) => ev.id === 'get1'));
    result.paramRead = got.parameters.find((p) => p.name === name)?.value;
    client.subscribeParameterUpdates([name]);
    client.setParameters([{ name, value: 0.4, type: 'float64' }], 'set1');
    await until('the update of the set', () => paramValue(name, 0.4));
    result.paramSet = 0.4;
    if (args.rosbridge) {
      const ROSLIB = await import('roslib2');
      const ros = new ROSLIB.Ros({ url: args.rosbridge });
      await new Promise((resolve, reject) => { ros.on('connection', resolve); ros.on('error', reject); });
      const param = new ROSLIB.Param({ ros, name: '/virtual_robot:robot.max_linear_velocity' });
      await new Promise((resolve, reject) => param.set(0.45, resolve, (e) => reject(new Error(String(e)))));
      await until('the update of the rosbridge set', () => paramValue(name, 0.45));
      result.paramFromRosbridge = 0.45;
      // a service a rosbridge client provides: advertised here, called with CDR
      const add = new ROSLIB.Service({ ros, name: '/foxtest/add_two_ints', serviceType: 'example_interfaces/srv/AddTwoInts' });
      add.advertise((req, resp) => { resp.sum = req.a + req.b; return true; });
      await until('the client-provided service', () => services.has('/foxtest/add_two_ints'));
      const answer = await call('/foxtest/add_two_ints', { a: 2n, b: 40n });
      const svc = services.get('/foxtest/add_two_ints');
      const reader = new MessageReader(parse(svc.response?.schema ?? svc.responseSchema, { ros2: true }));
      result.clientServiceSum = Number(reader.readMessage(new Uint8Array(answer.data.buffer, answer.data.byteOffset, answer.data.byteLength)).sum);
      ros.close();
    }
  }
  if (args.graph) {
    client.subscribeConnectionGraph();
    await until('the connection graph', () => graph.published.get(`${ns}/cmd_vel`) && graph.services.has('/reset'));
    result.graph = {
      odomPublishers: graph.published.get(`${ns}/odom`),
      odomSubscribers: graph.subscribed.get(`${ns}/odom`),
      cmdVelPublishers: graph.published.get(`${ns}/cmd_vel`),
      resetProviders: graph.services.get('/reset'),
    };
  }
  if (args.time) {
    await until('server time', () => times.length >= 2);
    result.times = times.length;
  }
  result.statuses = statuses.map((s) => s.message);
  const closed = new Promise((resolve) => { ws.once('close', resolve); setTimeout(resolve, 1000); });
  client.close();
  await closed;
  return result;
}

ws.on('unexpected-response', (_req, res) => finish(false, `handshake refused: HTTP ${res.statusCode}`));
main().then((r) => finish(true, r), (e) => finish(false, e.stack || String(e)));
