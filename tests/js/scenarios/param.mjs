// ROSLIB.Param against rosapi: get args.name, set it to args.value, get it again.
import { withTimeout } from '../lib.mjs';

function get(param, ms) {
  return withTimeout(
    new Promise((resolve, reject) => param.get((v) => resolve(v), (e) => reject(new Error(String(e))))),
    ms,
    `get ${param.name}`,
  );
}

function set(param, value, ms) {
  return withTimeout(
    new Promise((resolve, reject) => param.set(value, (r) => resolve(r ?? null), (e) => reject(new Error(String(e))))),
    ms,
    `set ${param.name}`,
  );
}

export default async function paramScenario(ROSLIB, ros, args) {
  const ms = args.timeout_ms ?? 5000;
  const param = new ROSLIB.Param({ ros, name: args.name });
  const before = await get(param, ms);
  const setResult = await set(param, args.value, ms);
  const after = await get(param, ms);
  return { before, setResult, after };
}
