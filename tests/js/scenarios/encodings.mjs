// Compressions side by side (one connection each, same topics), fragments out (2.x) and in,
// and latching. One Node process for the set.
import WebSocket from 'ws';
import { firstMessage, withTimeout, waitFor } from '../lib.mjs';

function open(ROSLIB, lib, url) {
  const opts = { url };
  if (lib === 'roslib1') opts.encoding = 'utf8';
  const r = new ROSLIB.Ros(opts);
  return withTimeout(
    new Promise((resolve, reject) => {
      r.on('connection', () => resolve(r));
      r.on('error', reject);
    }),
    5000,
    'connection',
  );
}

const plain = (v) => (ArrayBuffer.isView(v) ? Array.from(v, (x) => (typeof x === 'bigint' ? Number(x) : x)) : v);
const b64 = (u8) => Buffer.from(u8.buffer, u8.byteOffset, u8.byteLength).toString('base64');

export default async function encodings(ROSLIB, ros, args, lib, ctx) {
  const ms = args.timeout_ms ?? 5000;
  const out = {};
  const conns = {};
  for (const c of ['cbor', 'png', 'cbor-raw']) conns[c] = await open(ROSLIB, lib, ctx.url);
  try {
    const topic = (r, name, type, compression) => new ROSLIB.Topic({ ros: r, name, messageType: type, compression });
    const scans = await Promise.all([
      firstMessage(topic(ros, '/scan', 'sensor_msgs/msg/LaserScan', 'none'), ms),
      firstMessage(topic(conns.cbor, '/scan', 'sensor_msgs/msg/LaserScan', 'cbor'), ms),
      firstMessage(topic(conns.png, '/scan', 'sensor_msgs/msg/LaserScan', 'png'), ms),
      // no type: inferred by the server, as Lichtblick subscribes
      firstMessage(topic(conns['cbor-raw'], '/scan', undefined, 'cbor-raw'), ms),
    ]);
    const [none, cbor, png, raw] = scans;
    out.scan = {
      none: { frame: none.header.frame_id, n: none.ranges.length },
      cbor: {
        frame: cbor.header.frame_id,
        rangesTyped: cbor.ranges.constructor.name,
        n: cbor.ranges.length,
        first: plain(cbor.ranges).slice(0, 3),
        intensities: plain(cbor.intensities),
      },
      png: { frame: png.header.frame_id, n: png.ranges.length, first: png.ranges.slice(0, 3) },
      raw: { secs: raw.secs, nsecs: raw.nsecs, bytes: b64(raw.bytes) },
    };
    const odom = await firstMessage(topic(conns.cbor, '/odom', 'nav_msgs/msg/Odometry', 'cbor'), ms);
    out.odomCbor = { covariance: odom.pose.covariance.constructor.name, n: odom.pose.covariance.length, frame: odom.child_frame_id };
    // latching: one connection publishes once with latch, a later connection still receives it
    const latched = topic(ros, '/latched_note', 'std_msgs/msg/String', 'none');
    latched.latch = true;
    latched.publish({ data: 'kept for late subscribers' });
    await new Promise((r) => setTimeout(r, 100)); // let the publish reach the server first
    out.latched = await firstMessage(topic(conns.cbor, '/latched_note', 'std_msgs/msg/String', 'cbor'), ms);
    // a type simbridge does not know passes through between clients unchanged
    const custom = { a: 1, nested: { b: 'x', list: [1.5, null] } };
    const customGot = firstMessage(topic(conns.cbor, '/custom_thing', 'my_pkg/msg/Thing', 'none'), ms);
    await new Promise((r) => setTimeout(r, 100));
    topic(ros, '/custom_thing', 'my_pkg/msg/Thing', 'none').publish(custom);
    out.passThrough = await customGot;
    // fragments out: roslib 2.x reassembles them (1.4.1 cannot)
    if (lib === 'roslib2') {
      const fragments = [];
      const fragRos = await open(ROSLIB, lib, ctx.url);
      const sock = fragRos.transport?.socket;
      sock?.addEventListener?.('message', (ev) => {
        if (typeof ev.data === 'string' && ev.data.startsWith('{"op":"fragment"')) fragments.push(1);
      });
      const fragTopic = topic(fragRos, '/scan', 'sensor_msgs/msg/LaserScan', 'none');
      fragRos.callOnConnection({ op: 'subscribe', id: 'frag', topic: '/scan', type: 'sensor_msgs/msg/LaserScan', fragment_size: 1000 });
      const whole = await firstMessage(fragTopic, ms);
      out.fragmented = { n: whole.ranges.length, frame: whole.header.frame_id, pieces: fragments.length };
      // a service response in fragments too (fragment_size on call_service)
      const reply = await withTimeout(
        new Promise((resolve) => {
          fragRos.once('svc_frag', resolve);
          fragRos.callOnConnection({ op: 'call_service', id: 'svc_frag', service: '/rosapi/topics', args: {}, fragment_size: 256 });
        }),
        ms,
        'fragmented service response',
      );
      out.fragmentedService = { result: reply.result, hasOdom: reply.values.topics.includes('/odom') };
      fragRos.close();
    }
    // fragments in: a raw client sends a publish split into 3 fragments
    const echo = topic(ros, '/frag_in', 'std_msgs/msg/String', 'none');
    const got = firstMessage(echo, ms);
    await new Promise((r) => setTimeout(r, 100));
    const ws = new WebSocket(ctx.url);
    await withTimeout(new Promise((resolve, reject) => { ws.once('open', resolve); ws.once('error', reject); }), ms, 'raw ws');
    const text = JSON.stringify({ op: 'publish', topic: '/frag_in', type: 'std_msgs/msg/String', msg: { data: 'reassembled' } });
    const size = Math.ceil(text.length / 3);
    const pieces = [0, 1, 2].map((i) => text.slice(i * size, (i + 1) * size));
    for (const i of [2, 0, 1]) ws.send(JSON.stringify({ op: 'fragment', id: 'f1', num: i, total: 3, data: pieces[i] }));
    out.fragIn = await got;
    ws.close();
    return out;
  } finally {
    for (const r of Object.values(conns)) r.close();
  }
}
