// Bad-input probe: no roslib at all. Open a plain `ws` WebSocket to the URL,
// send args.frames in order, then collect every frame the server sends until
// args.collect_ms (default 500) have passed after the last send (an
// absence-of-more window) or the server closes the connection.
//
// args.frames: array of strings (sent as text frames) or {binary: "<base64>"}
// (sent as binary frames).
// Returns {replies, close}: replies are parsed JSON for text frames
// ({text: "..."} if a text frame is not JSON, {binary: "<base64>"} for binary
// frames); close is null or {code, reason} if the server closed the socket.
import WebSocket from 'ws';
import { withTimeout } from '../lib.mjs';

export const raw = true;

export default async function rawScenario(ROSLIB, ros, args, lib, ctx) {
  const frames = args.frames ?? [];
  const collectMs = args.collect_ms ?? 500;
  const replies = [];
  let close = null; // set only when the *server* closes the connection
  let closingByUs = false;

  const ws = new WebSocket(ctx.url);
  let closed;
  const closedPromise = new Promise((resolve) => {
    closed = resolve;
  });
  ws.on('message', (data, isBinary) => {
    if (isBinary) {
      replies.push({ binary: Buffer.from(data).toString('base64') });
      return;
    }
    const text = data.toString('utf8');
    try {
      replies.push(JSON.parse(text));
    } catch {
      replies.push({ text });
    }
  });
  ws.on('close', (code, reason) => {
    if (!closingByUs) close = { code, reason: reason.toString('utf8') };
    closed();
  });

  await withTimeout(
    new Promise((resolve, reject) => {
      ws.once('open', resolve);
      ws.once('error', reject);
    }),
    args.timeout_ms ?? 5000,
    `WebSocket open to ${ctx.url}`,
  );
  ws.on('error', (err) => console.error('[raw] socket error:', err.message));

  for (const frame of frames) {
    if (typeof frame === 'string') ws.send(frame);
    else if (frame && typeof frame.binary === 'string') ws.send(Buffer.from(frame.binary, 'base64'), { binary: true });
    else throw new Error(`bad frame spec: ${JSON.stringify(frame)}`);
  }

  // Absence-of-more window, cut short if the server hangs up.
  let timer;
  await Promise.race([closedPromise, new Promise((resolve) => { timer = setTimeout(resolve, collectMs); })]);
  clearTimeout(timer);

  if (!close) {
    closingByUs = true;
    ws.close();
    await Promise.race([closedPromise, new Promise((resolve) => setTimeout(resolve, 1000))]);
  }
  return { replies, close };
}
