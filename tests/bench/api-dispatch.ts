/**
 * The `/api/*` routes answered by the table's own dispatcher (routes/route.ts `dispatcher`) and by
 * Fastify (routes/fastify-api.ts), the same declared routes of the real gateway: GET /api/session
 * (a public route), GET /api/machines (a role check) and a 404, on loopback, one keep-alive
 * connection, each request after the last answer. Each server runs in its own child process (its
 * RSS its own), the two interleaved twice. Also the time to import Fastify and to make the API
 * ready; and Fastify alone in a bare process (api.ts imports it, so both servers load its code). Run: `npx tsx tests/bench/api-dispatch.ts [requests per path, default 5000]`.
 */
import { fork } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { fileURLToPath } from 'node:url';
import { percentile } from './gateway-load';

type Mode = 'own' | 'fastify';
const PATHS = ['/api/session', '/api/machines', '/api/no-such-thing'];

interface Ready {
  port: number;
  readyMs: number;
  rssMiB: number;
}

async function serve(mode: Mode): Promise<void> {
  const { createContext } = await import('../../gateway/context');
  const { apiRoutes } = await import('../../gateway/api');
  const { createAlarmStores } = await import('../../gateway/alarms');
  const { forceNoStore } = await import('../../gateway/answer-headers');
  const { dispatcher } = await import('../../gateway/routes/route');
  const fastifyModule = mode === 'fastify' ? await import('../../gateway/routes/fastify-api') : null;
  const dir = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-bench-'));
  const ctx = createContext({
    families: {},
    env: {},
    machines: { file: null, machines: [] },
    dataDir: dir,
    usersFile: path.join(dir, 'users.json'),
    watch: false,
  });
  const t2 = performance.now();
  const routes = apiRoutes(ctx, createAlarmStores(ctx));
  let api: (req: http.IncomingMessage, res: http.ServerResponse, url: URL) => Promise<void>;
  if (fastifyModule) {
    const f = fastifyModule.fastifyApi(routes, ctx);
    await f.ready;
    api = f;
  } else api = dispatcher(routes, ctx);
  const readyMs = performance.now() - t2;
  const server = http.createServer((req, res) => {
    forceNoStore(res);
    api(req, res, new URL(req.url ?? '/', 'http://gateway.local')).catch(() => res.destroy());
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  const ready: Ready = {
    port: (server.address() as AddressInfo).port,
    readyMs,
    rssMiB: process.memoryUsage().rss / 2 ** 20,
  };
  process.send?.({ ready });
  process.on('message', (m) => {
    if (m === 'rss') process.send?.({ rssMiB: process.memoryUsage().rss / 2 ** 20 });
    if (m === 'stop') {
      server.close();
      rmSync(dir, { recursive: true, force: true });
      process.exit(0);
    }
  });
}

function get(port: number, urlPath: string, agent: http.Agent): Promise<number> {
  return new Promise((resolve, reject) => {
    const req = http.get({ host: '127.0.0.1', port, path: urlPath, agent }, (res) => {
      res.resume();
      res.on('end', () => resolve(res.statusCode ?? 0));
    });
    req.on('error', reject);
  });
}

interface Run {
  mode: Mode;
  ready: Ready;
  byPath: Record<string, { status: number; medianMs: number; p99Ms: number }>;
  rssAfterMiB: number;
}

async function measure(mode: Mode, n: number): Promise<Run> {
  const child = fork(fileURLToPath(import.meta.url), ['--serve', mode], { execArgv: ['--import', 'tsx'] });
  const messages: Array<(m: unknown) => void> = [];
  child.on('message', (m) => messages.shift()?.(m));
  const next = <T>(): Promise<T> => new Promise((r) => messages.push((m) => r(m as T)));
  const { ready } = await next<{ ready: Ready }>();
  const agent = new http.Agent({ keepAlive: true, maxSockets: 1 });
  const byPath: Run['byPath'] = {};
  for (const p of PATHS) {
    let status = 0;
    for (let i = 0; i < 500; i++) status = await get(ready.port, p, agent); // warm-up
    const ms: number[] = [];
    for (let i = 0; i < n; i++) {
      const s = performance.now();
      status = await get(ready.port, p, agent);
      ms.push(performance.now() - s);
    }
    byPath[p] = { status, medianMs: percentile(ms, 50), p99Ms: percentile(ms, 99) };
  }
  agent.destroy();
  child.send('rss');
  const { rssMiB } = await next<{ rssMiB: number }>();
  child.send('stop');
  await new Promise((r) => child.once('exit', r));
  return { mode, ready, byPath, rssAfterMiB: rssMiB };
}

async function main(): Promise<void> {
  const n = Number(process.argv[2] ?? 5000);
  const runs: Run[] = [];
  for (const mode of ['own', 'fastify', 'own', 'fastify'] as const) runs.push(await measure(mode, n));
  const f = (x: number): string => x.toFixed(3);
  console.log(`${n} requests per path, one keep-alive connection, loopback`);
  for (const r of runs) {
    console.log(
      `${r.mode.padEnd(8)} ready ${r.ready.readyMs.toFixed(1)} ms, ` +
        `RSS ${r.ready.rssMiB.toFixed(1)} → ${r.rssAfterMiB.toFixed(1)} MiB`,
    );
    for (const [p, v] of Object.entries(r.byPath))
      console.log(`   ${p.padEnd(20)} ${v.status}  median ${f(v.medianMs)} ms  p99 ${f(v.p99Ms)} ms`);
  }
}

/** Fastify alone in a bare Node process: its import, an instance made ready, the RSS each adds. */
async function bare(): Promise<void> {
  const rss = (): number => process.memoryUsage().rss / 2 ** 20;
  const r0 = rss();
  const t0 = performance.now();
  const { default: Fastify } = await import('fastify');
  const t1 = performance.now();
  const r1 = rss();
  const app = Fastify({ logger: false });
  await app.ready();
  const t2 = performance.now();
  process.send?.({ importMs: t1 - t0, instanceMs: t2 - t1, rss: [r0, r1, rss()] });
}

async function measureBare(): Promise<void> {
  const child = fork(fileURLToPath(import.meta.url), ['--bare'], { execArgv: ['--import', 'tsx'] });
  const m = await new Promise<{ importMs: number; instanceMs: number; rss: number[] }>((r) =>
    child.once('message', (x) => r(x as never)),
  );
  await new Promise((r) => child.once('exit', r));
  const [r0, r1, r2] = m.rss.map((x) => x.toFixed(1));
  console.log(
    `Fastify alone: import ${m.importMs.toFixed(0)} ms, an instance ready ${m.instanceMs.toFixed(0)} ms; RSS ${r0} → ${r1} → ${r2} MiB`,
  );
}

const i = process.argv.indexOf('--serve');
if (i >= 0) void serve(process.argv[i + 1] as Mode);
else if (process.argv.includes('--bare')) await bare();
else {
  await main();
  for (let k = 0; k < 3; k++) await measureBare();
}
