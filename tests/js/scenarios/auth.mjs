// Authenticate with the rosbridge `auth` op through roslibjs's own Ros.authenticate (a rosauth
// MAC computed by the test), then list the topics: proof that the server let the client in.
// With args.expect_refusal, collect the status error and the close instead.
import { rosapi, waitFor } from '../lib.mjs';

export const allowClose = true;

export default async function auth(ROSLIB, ros, args) {
  const ms = args.timeout_ms ?? 5000;
  const statuses = [];
  let closed = false;
  const emit = ros.emit.bind(ros);
  ros.emit = (name, ...rest) => {
    if (typeof name === 'string' && name.startsWith('status')) statuses.push(rest[0]);
    if (name === 'close') closed = true;
    return emit(name, ...rest);
  };
  ros.authenticate(args.mac, args.client, args.dest, args.rand, args.t, args.level, args.end);
  if (args.expect_refusal) {
    await waitFor(() => closed, ms, 'the server closing the connection');
    return { statuses, closed };
  }
  const res = await rosapi(ros, 'getTopics', [], ms);
  return { topics: res.topics, statuses };
}
