/**
 * Gateway: proxied requests per second, the latency the gateway adds (p50/p95), for one machine
 * and for 100, and the server's memory per open browser socket (issue 16).
 *
 * One simulated controller per family runs here as a real HTTP + WebSocket server
 * (gateway/sim-server.ts `startSimFleet`, as `npm run sim`); the production server runs as a
 * child process (harness.ts `startServer`, open mode) with a machines file naming them by URL, so
 * the gateway proxies over TCP as it does for hardware.
 *
 * Requests and latency: a closed loop of keep-alive connections (each sends its next GET when the
 * last is answered), counted for BENCH_GATEWAY_SECONDS after a 1 s warm-up, first straight to the
 * simulators, then the same requests through the gateway (`/machines/<id>/…`). Added latency =
 * gateway percentile − direct percentile. Each family's request is a cheap read the gateway
 * forwards and never shares (`READS`, checked against the family's `shareRead` and access rule at
 * start): a shared read would measure the gateway's cache, not its proxy.
 * - "1 machine": a g2core (`GET /version`; keep-alive upstream, at most 2 reads upstream at once,
 *   so with 8 connections 6 wait in the gateway's queue for the machine: that wait is counted);
 *   with 1 connection (no queue anywhere) and with 8.
 * - "100 machines": 20 per family, each family's 20 pointing at its one simulator, requests
 *   round-robin over the 100. The gateway's watch runs in the background for every machine
 *   (polls every 5–10 s; the Duet, Prunt and xTool streams stay open, Prunt ticking once a
 *   second): its load is part of this case.
 * Target: added latency p95 ≤ 5 ms on localhost (`target_added_p95_ms`); requests/s as measured.
 * Beside them, less sensitive to other work on the machine: `server_cpu_ms_per_req`, the server
 * process's CPU (/proc/<pid>/stat) per proxied request, its CPU over the direct run (background:
 * the watch; `server_cpu_idle_pct`) taken out; and `upstream_per_req`, requests that reached the
 * simulators per proxied request (1 when nothing is shared; the watch's polls add a little).
 *
 * Memory: a server with one Prunt, started with the inspector (`--inspect=127.0.0.1:0` in
 * NODE_OPTIONS, bench only); N browser sockets (BENCH_GATEWAY_SOCKETS, default 200) on its shared
 * stream `/machines/<id>/websocket/everything` with the console's Origin, each asking for 5
 * ticks/s as a machine page does (divisor "4"). After 5 sockets opened and closed (code paths
 * compiled) and RSS holding still (it drops by some 15 MiB about 16 s after start, idle or not:
 * at least 22 s, at most 45 s), the sockets are opened in four steps (0, N/4 … N). At each step,
 * once they have received frames for 4 s, the server collects its garbage (DevTools Protocol
 * `HeapProfiler.collectGarbage`, twice), its `process.memoryUsage()` is read, and its RSS
 * (/proc/<pid>/status VmRSS; the pid found by the port it listens on) sampled for 2 s (median).
 * `rss_bytes_per_socket` = (RSS with N − RSS with 0) / N; likewise the V8 heap and external
 * memory; `…_fit` is the least-squares slope over the five steps. Kernel socket buffers are not
 * in RSS. No target.
 *
 * The simulators and the load run in this process, on the same 2 cores as the server: the
 * figures are for this machine, compare them within one report.
 *
 * `BENCH_GATEWAY_SECONDS=3 node --expose-gc --import tsx tests/bench/gateway.bench.ts` for a
 * quick run; `npm run bench -- gateway` for the report. Needs a built dist/ (built when missing).
 */
import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { WebSocket } from 'ws';
import { startSimFleet, type SimFleet, type SimServer } from '../../gateway/sim-server';
import { families } from '../../src/controllers/families';
import type { MachineKind } from '../../src/fleet/types';
import {
  childListeningOn,
  cpuSeconds,
  get,
  percentile,
  Inspector,
  rssBytes,
  runLoad,
  type LoadResult,
} from './gateway-load';
import { ensureDist, sleep, startServer, type Server } from './harness';
import { median, report, round } from './util';

const SECONDS = Number(process.env.BENCH_GATEWAY_SECONDS ?? 10);
const SOCKETS = Number(process.env.BENCH_GATEWAY_SOCKETS ?? 200);
const WARMUP_SECONDS = 1;
const CONNECTIONS = 8;
const PER_FAMILY = 20;
const TARGET_ADDED_P95_MS = 5;
/** The machine page's Prunt divisor at 5 Hz (prunt/state.ts `divisorFor(5)`): a tick every 200 ms. */
const PRUNT_DIVISOR = '4';
/** Before the first memory reading: at least this long after the server is up, at most the other. */
const RSS_SETTLE_MIN_MS = 22_000;
const RSS_SETTLE_MAX_MS = 45_000;
/** Sockets receive frames this long before the server's memory is read. */
const SOCKET_SETTLE_MS = 4000;

/**
 * A cheap read per family that the gateway forwards and never shares (checked in `checkReads`):
 * - g2core `/version`, xTool `/ping`, Prunt `/uploads`: paths the family never shares;
 * - Duet `/machine/noop` and TouchCut `rest/v1/machine-info` are shared only without a query (or
 *   only with the parameters the console sends): `?bench=1` makes them unshared, and the access
 *   rules read them by path, so they stay viewer reads.
 */
const READS: Record<MachineKind, string> = {
  g2core: '/version',
  xtool: '/ping',
  prunt: '/uploads',
  duet: '/machine/noop?bench=1',
  touchcut: '/rest/v1/machine-info?bench=1',
};
const KINDS: MachineKind[] = ['g2core', 'xtool', 'prunt', 'duet', 'touchcut'];

interface Entry {
  id: string;
  name: string;
  kind: MachineKind;
  url: string;
  wsUrl?: string;
}

const log = (msg: string): void => {
  process.stderr.write(`gateway.bench: ${msg}\n`);
};

/** Fails when a chosen read would be shared (the cache measured) or is not a plain viewer read. */
function checkReads(): void {
  for (const kind of KINDS) {
    const fam = families[kind];
    const u = new URL(READS[kind], 'http://x');
    const shared = fam.gateway?.sharing?.shareRead?.(u.pathname, new URLSearchParams(u.search));
    if (shared !== undefined && shared !== null)
      throw new Error(`${kind}: GET ${READS[kind]} is shared for ${shared} ms: pick another read`);
    const d = fam.access({ method: 'GET', path: u.pathname, query: new URLSearchParams(u.search) });
    if (d.command || d.role !== 'viewer')
      throw new Error(`${kind}: GET ${READS[kind]} is not a viewer read (${d.role}: ${d.label})`);
  }
}

function entryFor(sim: SimServer, id: string): Entry {
  return {
    id,
    name: id,
    kind: sim.kind,
    url: sim.url,
    ...(sim.wsUrl ? { wsUrl: sim.wsUrl } : {}),
  };
}

function simOf(fleet: SimFleet, kind: MachineKind): SimServer {
  const s = fleet.servers.find((x) => x.kind === kind);
  if (!s) throw new Error(`no simulator for ${kind}`);
  return s;
}

/** Waits until every URL answers 2xx through the gateway (the held sessions are opened on demand). */
async function ready(urls: string[]): Promise<void> {
  const agent = new http.Agent({ keepAlive: false });
  try {
    for (const u of new Set(urls)) {
      const until = performance.now() + 15_000;
      for (;;) {
        let why: string;
        try {
          const status = await get(u, agent);
          if (status >= 200 && status <= 299) break;
          why = `HTTP ${status}`;
        } catch (e) {
          why = e instanceof Error ? e.message : String(e);
        }
        if (performance.now() > until) throw new Error(`${u} does not answer: ${why}`);
        await sleep(200);
      }
    }
  } finally {
    agent.destroy();
  }
}

// ---------------------------------------------------------------- requests and latency

interface LoadCase {
  name: string;
  machines: Entry[];
  /** The simulators behind `machines` (their request counters). */
  sims: SimServer[];
  connections: number;
}

const pct = (r: LoadResult, p: number): number => round(percentile(r.latencies, p), 3);
const perSecond = (r: LoadResult): number => round(r.requests / r.seconds, 1);

async function runLoadCase(c: LoadCase, base: string): Promise<void> {
  const direct = c.machines.map((m) => m.url + READS[m.kind]);
  const proxied = c.machines.map((m) => `${base}/machines/${m.id}${READS[m.kind]}`);
  await ready(proxied);
  const pid = childListeningOn(Number(new URL(base).port));
  const load = (urls: string[]): Promise<LoadResult> =>
    runLoad({ urls, connections: c.connections, seconds: SECONDS, warmupSeconds: WARMUP_SECONDS });
  log(`${c.name}: direct…`);
  // The server's CPU meanwhile: its background work (the watch) over the same time.
  let cpu0 = cpuSeconds(pid);
  const d = await load(direct);
  const idleCpu = cpuSeconds(pid) - cpu0;
  log(`${c.name}: through the gateway…`);
  for (const sim of c.sims) sim.resetStats();
  cpu0 = cpuSeconds(pid);
  const g = await load(proxied);
  const proxyCpu = cpuSeconds(pid) - cpu0;
  const upstream = c.sims.reduce((a, sim) => a + sim.stats().requests, 0);
  for (const [what, r] of [
    ['direct', d],
    ['gateway', g],
  ] as const)
    if (r.errors) log(`${c.name}, ${what}: ${r.errors} failed requests, the first: ${r.firstError}`);
  const addedP50 = round(pct(g, 50) - pct(d, 50), 3);
  const addedP95 = round(pct(g, 95) - pct(d, 95), 3);
  const misses = [
    addedP95 <= TARGET_ADDED_P95_MS ? '' : `added p95 ${addedP95} ms`,
    g.errors + d.errors ? `${g.errors + d.errors} failed requests` : '',
  ].filter(Boolean);
  const kinds = [...new Set(c.machines.map((m) => m.kind))];
  report({
    name: c.name,
    machines: c.machines.length,
    connections: c.connections,
    seconds: SECONDS,
    reads: kinds.map((k) => `${k} GET ${READS[k]}`).join(', '),
    ...(kinds.length === 1 && kinds[0]
      ? { upstream_reads_at_once: families[kinds[0]].gateway?.sharing?.maxConcurrentReads ?? null }
      : {}),
    gateway_req_per_s: perSecond(g),
    direct_req_per_s: perSecond(d),
    gateway_p50_ms: pct(g, 50),
    gateway_p95_ms: pct(g, 95),
    direct_p50_ms: pct(d, 50),
    direct_p95_ms: pct(d, 95),
    added_p50_ms: addedP50,
    added_p95_ms: addedP95,
    target_added_p95_ms: TARGET_ADDED_P95_MS,
    // The server's CPU per proxied request, its background CPU over the same time taken out.
    server_cpu_ms_per_req: g.sent ? round(((proxyCpu - idleCpu) * 1000) / g.sent, 3) : null,
    server_cpu_idle_pct: round((idleCpu / (SECONDS + WARMUP_SECONDS)) * 100, 1),
    // Requests that reached the simulators per proxied request (≈ 1: nothing shared; the watch adds a few).
    upstream_per_req: g.sent ? round(upstream / g.sent, 3) : null,
    failed: g.errors + d.errors,
    meets: misses.length ? `no: ${misses.join(', ')}` : 'yes',
  });
}

// ---------------------------------------------------------------- memory per socket

interface Viewer {
  ws: WebSocket;
  frames: number;
}

function openViewer(url: string, origin: string): Promise<Viewer> {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url, { origin, perMessageDeflate: false });
    const v: Viewer = { ws, frames: 0 };
    ws.on('message', () => v.frames++);
    ws.once('unexpected-response', (_req, res) => {
      reject(new Error(`${url}: HTTP ${res.statusCode ?? '?'} instead of a WebSocket`));
      ws.terminate();
    });
    ws.once('error', reject);
    ws.once('open', () => {
      ws.off('error', reject);
      ws.on('error', () => undefined);
      ws.send(PRUNT_DIVISOR);
      resolve(v);
    });
  });
}

async function openViewers(n: number, url: string, origin: string, into: Viewer[]): Promise<void> {
  const BATCH = 20;
  for (let done = 0; done < n; done += BATCH) {
    const opened = await Promise.allSettled(
      Array.from({ length: Math.min(BATCH, n - done) }, () => openViewer(url, origin)),
    );
    for (const o of opened) if (o.status === 'fulfilled') into.push(o.value);
    const failed = opened.find((o) => o.status === 'rejected');
    if (failed) throw failed.reason;
  }
}

/** The median of the server's RSS sampled every 100 ms for 2 s. */
async function sampleRss(pid: number): Promise<number> {
  const xs: number[] = [];
  for (let i = 0; i < 20; i++) {
    xs.push(rssBytes(pid));
    await sleep(100);
  }
  return median(xs);
}

/** Least-squares slope of y over x. */
function slope(xs: number[], ys: number[]): number {
  const mx = xs.reduce((a, x) => a + x, 0) / xs.length;
  const my = ys.reduce((a, y) => a + y, 0) / ys.length;
  let num = 0;
  let den = 0;
  xs.forEach((x, i) => {
    num += (x - mx) * ((ys[i] as number) - my);
    den += (x - mx) ** 2;
  });
  return den ? num / den : Number.NaN;
}

async function runMemoryCase(server: Server, id: string, viewers: Viewer[]): Promise<void> {
  const port = Number(new URL(server.base).port);
  const pid = childListeningOn(port);
  const inspector = await Inspector.of(pid, port);
  try {
    const url = `${server.base.replace(/^http/, 'ws')}/machines/${id}/websocket/everything`;
    // Warm-up: the first sockets compile the code paths.
    const warm: Viewer[] = [];
    try {
      await openViewers(5, url, server.base, warm);
      await sleep(1000);
    } finally {
      for (const v of warm) v.ws.close();
    }
    // The server's RSS drops by some 15 MiB about 16 s after it starts (memory given back
    // late): wait for that, and for RSS to hold still, before the first reading.
    const settleFrom = performance.now();
    const recent: number[] = [];
    for (let i = 0; ; i++) {
      if (i % 5 === 0) await inspector.memoryAfterGc();
      recent.push(rssBytes(pid));
      if (recent.length > 6) recent.shift();
      const age = performance.now() - settleFrom;
      const still = recent.length === 6 && Math.max(...recent) - Math.min(...recent) < 2 ** 20;
      if ((age >= RSS_SETTLE_MIN_MS && still) || age >= RSS_SETTLE_MAX_MS) break;
      await sleep(1000);
    }
    const counts = [0, 1, 2, 3, 4].map((k) => Math.round((SOCKETS * k) / 4));
    const heap: number[] = [];
    const external: number[] = [];
    const rss: number[] = [];
    let framesPerSocketPerS = 0;
    for (const n of counts) {
      if (n > viewers.length) await openViewers(n - viewers.length, url, server.base, viewers);
      const frames = (): number => viewers.reduce((a, v) => a + v.frames, 0);
      const f0 = frames();
      const t0 = performance.now();
      await sleep(SOCKET_SETTLE_MS);
      if (viewers.length)
        framesPerSocketPerS = round((frames() - f0) / viewers.length / ((performance.now() - t0) / 1000), 2);
      const m = await inspector.memoryAfterGc();
      heap.push(m.heapUsed);
      external.push(m.external);
      rss.push(await sampleRss(pid));
    }
    const open = viewers.filter((v) => v.ws.readyState === WebSocket.OPEN).length;
    const silent = viewers.filter((v) => v.frames === 0).length;
    if (open < SOCKETS) log(`only ${open} of ${SOCKETS} sockets are still open`);
    const mib = (b: number): number => round(b / 2 ** 20, 2);
    const steps = (xs: number[]): Record<number, number> =>
      Object.fromEntries(counts.map((n, i) => [n, mib(xs[i] ?? Number.NaN)]));
    const perSocket = (xs: number[]): number =>
      Math.round(((xs[xs.length - 1] ?? Number.NaN) - (xs[0] ?? Number.NaN)) / SOCKETS);
    report({
      name: 'gateway: memory per browser socket',
      sockets: SOCKETS,
      sockets_open: open,
      sockets_without_frames: silent,
      stream: `prunt /machines/${id}/websocket/everything, divisor ${PRUNT_DIVISOR}`,
      frames_per_socket_per_s: framesPerSocketPerS,
      rss_bytes_per_socket: perSocket(rss),
      rss_bytes_per_socket_fit: Math.round(slope(counts, rss)),
      heap_bytes_per_socket: perSocket(heap),
      heap_bytes_per_socket_fit: Math.round(slope(counts, heap)),
      external_bytes_per_socket: perSocket(external),
      rss_mib: steps(rss),
      heap_used_mib: steps(heap),
      external_mib: steps(external),
    });
  } finally {
    inspector.close();
  }
}

// ---------------------------------------------------------------- main

async function main(): Promise<void> {
  if (!Number.isFinite(SECONDS) || SECONDS <= 0)
    throw new Error(
      `BENCH_GATEWAY_SECONDS must be a positive number, not ${process.env.BENCH_GATEWAY_SECONDS}`,
    );
  if (!Number.isInteger(SOCKETS) || SOCKETS < 2)
    throw new Error(`BENCH_GATEWAY_SOCKETS must be an integer ≥ 2, not ${process.env.BENCH_GATEWAY_SOCKETS}`);
  checkReads();
  ensureDist();
  const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-gateway-'));
  let fleet: SimFleet | null = null;
  let server: Server | null = null;
  const viewers: Viewer[] = [];
  const closeViewers = (): void => {
    for (const v of viewers.splice(0)) v.ws.terminate();
  };
  const stopServer = async (): Promise<void> => {
    closeViewers();
    await server?.stop().catch(() => undefined);
    server = null;
  };
  const cleanup = async (): Promise<void> => {
    await stopServer();
    await fleet?.close().catch(() => undefined);
    fleet = null;
    rmSync(work, { recursive: true, force: true });
  };
  const onSignal = (): void => {
    void cleanup().then(() => process.exit(130));
  };
  process.once('SIGINT', onSignal);
  process.once('SIGTERM', onSignal);
  /** A fresh server for `machines` (its own data directory). */
  const serve = async (label: string, machines: Entry[], env: NodeJS.ProcessEnv = {}): Promise<Server> => {
    await stopServer();
    const dir = path.join(work, label);
    mkdirSync(dir);
    const file = path.join(work, `${label}.json`);
    writeFileSync(file, JSON.stringify({ machines }, null, 2));
    server = await startServer(dir, file, env);
    return server;
  };
  try {
    fleet = await startSimFleet(families);
    log(
      `${SECONDS} s per measurement, ${CONNECTIONS} connections, ${SOCKETS} sockets: ` +
        `about ${Math.ceil(6 * (SECONDS + WARMUP_SECONDS) + 70)} s`,
    );

    const one = [entryFor(simOf(fleet, 'g2core'), 'g2core-1')];
    let s = await serve('one', one);
    for (const connections of [1, CONNECTIONS])
      await runLoadCase(
        {
          name: `gateway: 1 machine, ${connections} connection${connections > 1 ? 's' : ''}`,
          machines: one,
          sims: [simOf(fleet, 'g2core')],
          connections,
        },
        s.base,
      );

    // Interleaved (g2core-1, xtool-1, …, g2core-2, …): consecutive requests go to other families.
    const hundred: Entry[] = [];
    for (let i = 1; i <= PER_FAMILY; i++)
      for (const kind of KINDS) hundred.push(entryFor(simOf(fleet, kind), `${kind}-${i}`));
    s = await serve('hundred', hundred);
    await runLoadCase(
      {
        name: `gateway: ${hundred.length} machines, ${CONNECTIONS} connections`,
        machines: hundred,
        sims: fleet.servers,
        connections: CONNECTIONS,
      },
      s.base,
    );

    log('memory per browser socket…');
    // The inspector (localhost, any free port) to collect the garbage before each reading.
    const inspect = `${process.env.NODE_OPTIONS ?? ''} --inspect=127.0.0.1:0`.trim();
    s = await serve('sockets', [entryFor(simOf(fleet, 'prunt'), 'prunt-1')], { NODE_OPTIONS: inspect });
    await runMemoryCase(s, 'prunt-1', viewers);
  } finally {
    process.off('SIGINT', onSignal);
    process.off('SIGTERM', onSignal);
    await cleanup();
  }
}

main().catch((e: unknown) => {
  log(e instanceof Error ? e.message : String(e));
  process.exit(1);
});
