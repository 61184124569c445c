// Round trip through the bridge: advertise /chatter (std_msgs/msg/String)
// with one Topic object, subscribe with a second Topic object, publish
// args.text once and wait for it to come back. Then keep listening for
// args.dup_window_ms (default 500) to prove it arrives exactly once -- that
// fixed wait is an absence check, not a synchronisation.
// Returns {sent, messages: [msg...], times: [ms...], latency_ms}.
import { makeMessage, makeTopic, now, sleep, waitFor } from '../lib.mjs';

export default async function chatter(ROSLIB, ros, args, lib) {
  const text = args.text ?? 'hello from roslibjs';
  const timeoutMs = args.timeout_ms ?? 5000;
  const dupWindowMs = args.dup_window_ms ?? 500;
  const type = 'std_msgs/msg/String';

  const pub = makeTopic(ROSLIB, ros, '/chatter', type);
  const sub = makeTopic(ROSLIB, ros, '/chatter', type);
  const messages = [];
  const times = [];
  sub.subscribe((msg) => {
    messages.push(msg);
    times.push(now());
  });
  pub.advertise();

  // The bridge handles one client's ops in order, so advertise + subscribe
  // are in place before this publish is processed.
  const sentAt = now();
  pub.publish(makeMessage(ROSLIB, lib, { data: text }));
  await waitFor(() => messages.length > 0, timeoutMs, `echo of "${text}" on /chatter`);
  await sleep(dupWindowMs);

  sub.unsubscribe();
  pub.unadvertise();
  return { sent: text, messages, times, latency_ms: times[0] - sentAt };
}
