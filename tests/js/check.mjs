// Sanity check of the installed harness dependencies: `node check.mjs`
// (or `npm run check`). Prints one JSON line with the versions found and
// exits 1 if any library cannot be imported the way run.mjs imports it.
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const out = { node: process.version };
let ok = true;
for (const [key, load] of [
  ['roslib1', async () => (await import('roslib1')).default.REVISION],
  ['roslib2', async () => (await import('roslib2')).REVISION],
  ['ws', async () => require('ws/package.json').version],
  ['playwright-core', async () => (await import('playwright-core')) && require('playwright-core/package.json').version],
]) {
  try {
    out[key] = await load();
  } catch (err) {
    ok = false;
    out[key] = `ERROR: ${err.message}`;
  }
}
// roslib 2.1.0 only uses the `ws` package when there is no global WebSocket.
out.roslib2_transport = typeof WebSocket === 'function' ? 'global WebSocket' : 'ws';
console.log(JSON.stringify({ ok, ...out }));
process.exit(ok ? 0 : 1);
