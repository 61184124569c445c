#!/usr/bin/env node
// Run one client scenario with an unmodified roslibjs against a rosbridge URL.
//
//   node run.mjs --lib roslib1|roslib2 --url ws://127.0.0.1:PORT --scenario NAME
//                [--args JSON] [--timeout-ms N]
//
// Contract (relied upon by pytest):
//   * stdout carries exactly one line, the last thing printed:
//       {"ok":true,"result":<scenario return value>}   exit code 0
//       {"ok":false,"error":"<message>"}                exit code 1
//     Everything else (library chatter, console.log, diagnostics) goes to
//     stderr: console.log/info/debug are redirected there before anything is
//     loaded.
//   * The scenario module ./scenarios/NAME.mjs default-exports
//       async function (ROSLIB, ros, args, lib, ctx) -> JSON-serialisable result
//     (`ctx` = {url, timeoutMs}; `args` is the parsed --args, default {})
//     and may also export:
//       raw = true         do not create a Ros connection; `ros` is null
//       allowClose = true  the connection closing mid-scenario is not an error
//       allowError = true  'error' events after connecting are not an error
//   * A connection that errors/closes before 'connection', an exception, an
//     unhandled rejection or the global timeout (default 20000 ms, covering
//     connect + scenario) all give ok:false. The Ros connection is closed
//     before the final line is printed.

import { parseArgs } from 'node:util';
import { fileURLToPath, pathToFileURL } from 'node:url';
import path from 'node:path';

// Keep stdout for the single result line.
const stderrLog = (...a) => console.error(...a);
console.log = stderrLog;
console.info = stderrLog;
console.debug = stderrLog;

const HERE = path.dirname(fileURLToPath(import.meta.url));
const LIBS = ['roslib1', 'roslib2'];

let ros = null;
let finished = false;

function errorText(err) {
  if (err instanceof Error) return err.message || String(err);
  if (err && typeof err === 'object') {
    // ws ErrorEvent / CloseEvent and friends
    if (err.message) return String(err.message);
    if (err.error instanceof Error) return err.error.message;
    if ('code' in err && 'reason' in err) return `code ${err.code} reason ${JSON.stringify(String(err.reason))}`;
    try {
      return JSON.stringify(err);
    } catch {
      return String(err);
    }
  }
  return String(err);
}

/** Close `ros` and wait (bounded) for its 'close' event. */
function closeRos(timeoutMs = 1000) {
  if (!ros) return Promise.resolve();
  const r = ros;
  return new Promise((resolve) => {
    const timer = setTimeout(resolve, timeoutMs);
    try {
      r.once('close', () => {
        clearTimeout(timer);
        resolve();
      });
      r.close();
    } catch {
      clearTimeout(timer);
      resolve();
    }
  });
}

/** Print the one result line and exit. Only the first call has any effect. */
async function finish(ok, payload) {
  if (finished) return;
  finished = true;
  let line;
  if (ok) {
    try {
      line = JSON.stringify({ ok: true, result: payload === undefined ? null : payload });
    } catch (err) {
      ok = false;
      line = JSON.stringify({ ok: false, error: `result is not JSON-serialisable: ${errorText(err)}` });
    }
  } else {
    line = JSON.stringify({ ok: false, error: errorText(payload) });
  }
  await closeRos();
  process.stdout.write(line + '\n', () => process.exit(ok ? 0 : 1));
}

process.on('uncaughtException', (err) => {
  console.error('[run.mjs] uncaught exception:', err);
  finish(false, `uncaught exception: ${errorText(err)}`);
});
// A scenario awaiting something that can never happen (no timers, no
// sockets left) would otherwise let Node exit silently with code 0.
process.on('beforeExit', () => finish(false, 'event loop drained before the scenario finished'));
process.on('unhandledRejection', (err) => {
  console.error('[run.mjs] unhandled rejection:', err);
  finish(false, `unhandled rejection: ${errorText(err)}`);
});

/** Load a library and return the object scenarios call `ROSLIB`. */
async function loadLib(lib) {
  if (lib === 'roslib1') {
    // roslib 1.4.1 is CommonJS; its package "main" (src/RosLibNode.js) is the
    // Node build: ROSLIB with Ros = RosTCP, which hands ws:// URLs to the core
    // Ros, which does `new (require('ws'))(url)` with binaryType arraybuffer.
    return (await import('roslib1')).default;
  }
  // roslib 2.1.0 is ESM-only ("exports": {".": {"import": "./dist/RosLib.js"}}).
  // Its default transportFactory uses the global WebSocket if there is one
  // (Node >= 22) and otherwise `await import("ws")` (Node 20).
  return import('roslib2');
}

/** Describe which WebSocket implementation the Ros instance ended up using. */
async function transportName(lib, r) {
  const { WebSocket: WsWebSocket } = await import('ws');
  const sock = lib === 'roslib1' ? r.socket : r.transport?.socket;
  if (!sock) return 'none';
  return sock instanceof WsWebSocket ? 'ws' : sock.constructor?.name || typeof sock;
}

function connect(ROSLIB, lib, url) {
  return new Promise((resolve, reject) => {
    const opts = { url };
    // RosTCP (1.4.1 Node main) prints a console.error about TCP encoding
    // unless `encoding` is given; it is unused for ws:// URLs.
    if (lib === 'roslib1') opts.encoding = 'utf8';
    const r = new ROSLIB.Ros(opts);
    ros = r;
    const onConn = () => {
      cleanup();
      resolve(r);
    };
    const onErr = (e) => {
      cleanup();
      reject(new Error(`connection error: ${errorText(e)}`));
    };
    const onClose = (e) => {
      cleanup();
      reject(new Error(`connection closed before open: ${errorText(e)}`));
    };
    function cleanup() {
      r.off('connection', onConn);
      r.off('error', onErr);
      r.off('close', onClose);
    }
    r.on('connection', onConn);
    r.on('error', onErr);
    r.on('close', onClose);
  });
}

async function main() {
  const { values } = parseArgs({
    options: {
      lib: { type: 'string' },
      url: { type: 'string' },
      scenario: { type: 'string' },
      args: { type: 'string', default: '{}' },
      'timeout-ms': { type: 'string', default: '20000' },
    },
    strict: true,
  });
  const { lib, url, scenario } = values;
  if (!LIBS.includes(lib)) throw new Error(`--lib must be one of ${LIBS.join(', ')}`);
  if (!scenario || !/^[A-Za-z0-9_-]+$/.test(scenario)) throw new Error('--scenario NAME is required');
  const timeoutMs = Number(values['timeout-ms']);
  if (!Number.isFinite(timeoutMs) || timeoutMs <= 0) throw new Error('--timeout-ms must be a positive number');
  let args;
  try {
    args = JSON.parse(values.args);
  } catch (err) {
    throw new Error(`--args is not valid JSON: ${err.message}`);
  }

  const timer = setTimeout(() => finish(false, `timeout after ${timeoutMs} ms`), timeoutMs);

  const mod = await import(pathToFileURL(path.join(HERE, 'scenarios', `${scenario}.mjs`)).href);
  if (typeof mod.default !== 'function') throw new Error(`scenario ${scenario} has no default export function`);

  if (!url) throw new Error('--url is required');
  // Fail fast on a malformed URL: roslib 1.4.1 would treat anything not
  // starting with ws:// or wss:// as a raw TCP address, and 2.1.0 only
  // console.error()s a rejected connect() (no 'error' event), i.e. a timeout.
  let parsed;
  try {
    parsed = new URL(url);
  } catch {
    throw new Error(`--url is not a valid URL: ${url}`);
  }
  if (parsed.protocol !== 'ws:' && parsed.protocol !== 'wss:') throw new Error(`--url must be ws:// or wss://, got ${url}`);
  let ROSLIB = null;
  if (!mod.raw) {
    ROSLIB = await loadLib(lib);
    await connect(ROSLIB, lib, url);
    console.error(`[run.mjs] ${lib} ${ROSLIB.REVISION} connected to ${url} via ${await transportName(lib, ros)}`);
    // After 'connection', a close or error is a failure unless the scenario
    // says it expects one.
    ros.on('close', (e) => {
      if (!mod.allowClose) finish(false, `connection closed during scenario: ${errorText(e)}`);
    });
    ros.on('error', (e) => {
      console.error('[run.mjs] ros error event:', e);
      if (!mod.allowError) finish(false, `ros error event: ${errorText(e)}`);
    });
  }

  const result = await mod.default(ROSLIB, ros, args, lib, { url, timeoutMs });
  clearTimeout(timer);
  await finish(true, result);
}

main().catch((err) => {
  console.error('[run.mjs] failed:', err);
  finish(false, err);
});
