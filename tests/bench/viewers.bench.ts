/**
 * Viewers: what the open pages cost each controller (issue "one upstream per machine").
 *
 * One simulated controller per family (xtool, touchcut, duet, prunt, g2core) runs here as a
 * real HTTP + WebSocket server (gateway/sim-server.ts, as `npm run sim`); the production server
 * runs as a child process (`node --import tsx server/main.ts`) with a machines file naming them
 * by URL; 0, 1, 5 and 10 Chromium contexts (each one viewer: its own tab, cookies, sockets)
 * keep the fleet page open for BENCH_VIEWER_SECONDS (default 60) each, and a last case keeps
 * the 10 viewers open with their pages hidden. Counting starts 3 s after the case's pages show
 * every machine Online (page loads are not counted), so the numbers are the steady cost. The
 * simulators count what reaches them (`SimServer.stats()`): HTTP requests, TCP connections,
 * WebSockets. One JSON line per (case, family) and per case for all families together, rates
 * per minute, ratios to one viewer, and the targets beside them:
 * - requests/min with N viewers ≤ 1.2 × one viewer's, per controller;
 * - at most one upstream socket per machine (`ws_open_max` ≤ 1);
 * - TCP connections/min ≤ one viewer's requests/min (kept-alive connections, not one per request).
 *
 * Hidden pages: headless Chromium reports every page as visible (minimising its window, a
 * background tab or CDP `Page.setWebLifecycleState` do not change `document.visibilityState`),
 * so the page's `document.visibilityState`/`document.hidden` are overridden to "hidden"/true and
 * `visibilitychange` is dispatched, which is what the console listens to. Chromium's timer
 * throttling of real background tabs is not emulated, so hidden numbers are an upper bound.
 *
 * `BENCH_VIEWER_SECONDS=10 npx tsx tests/bench/viewers.bench.ts` for a quick run;
 * `npm run bench -- viewers` for the report. Needs a built dist/ (built here when missing).
 */
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { type Browser, type BrowserContext, type Page } from '@playwright/test';
import { startSimFleet, type SimFleet, type SimServer, type SimServerStats } from '../../gateway/sim-server';
import { families } from '../../src/controllers/families';
import { launchChromium, stopOnSignal, ensureDist, sleep, startServer, type Server } from './harness';
import { report, round } from './util';

const SECONDS = Number(process.env.BENCH_VIEWER_SECONDS ?? 60);
/** After the pages are loaded (or hidden), before counting starts. */
const WARMUP_MS = 3000;
const TARGET_RATIO = 1.2;

interface Case {
  name: string;
  viewers: number;
  hidden: boolean;
}

// Viewers are only added (1, then 4 more, then 5 more; the last case hides those 10), so no page
// load is repeated and "no viewer" comes first: a gateway that keeps a machine's link for a while
// after its last viewer leaves would otherwise charge it to "no viewer".
const CASES: Case[] = [
  { name: 'no viewer', viewers: 0, hidden: false },
  { name: '1 viewer', viewers: 1, hidden: false },
  { name: '5 viewers', viewers: 5, hidden: false },
  { name: '10 viewers', viewers: 10, hidden: false },
  { name: '10 viewers, hidden', viewers: 10, hidden: true },
];

interface Measured {
  family: string;
  seconds: number;
  stats: SimServerStats;
}

const log = (msg: string): void => {
  process.stderr.write(`viewers.bench: ${msg}\n`);
};

// ---------------------------------------------------------------- setup

// ---------------------------------------------------------------- viewers

/** Opens the fleet page in a fresh context and waits until every machine's tile reads Online. */
async function openViewer(browser: Browser, base: string, ids: string[]): Promise<BrowserContext> {
  const ctx = await browser.newContext({ viewport: { width: 1440, height: 900 } });
  try {
    const page = await ctx.newPage();
    await page.goto(`${base}/`);
    for (const id of ids)
      await page
        .getByTestId(`tile-${id}`)
        .getByTestId('tile-link')
        .filter({ hasText: 'Online' })
        .waitFor({ timeout: 30_000 });
    return ctx;
  } catch (e) {
    await ctx.close();
    throw e;
  }
}

/**
 * Makes the page believe it is hidden (see the header) and checks that it does. A string, not a
 * function: tsx would wrap a function's inner arrows in a helper the page does not have.
 */
const HIDE = `(() => {
  Object.defineProperty(document, 'visibilityState', { configurable: true, get() { return 'hidden'; } });
  Object.defineProperty(document, 'hidden', { configurable: true, get() { return true; } });
  document.dispatchEvent(new Event('visibilitychange'));
  return document.visibilityState;
})()`;

async function hide(page: Page): Promise<void> {
  const state: unknown = await page.evaluate(HIDE);
  if (state !== 'hidden') throw new Error(`could not hide the page (visibilityState ${String(state)})`);
}

async function onlineTiles(ctxs: BrowserContext[]): Promise<number> {
  let n = 0;
  for (const ctx of ctxs)
    for (const page of ctx.pages())
      n += await page.getByTestId('tile-link').filter({ hasText: 'Online' }).count();
  return n;
}

/**
 * Brings the open viewers up to the case's number (viewers are only ever added: the cases grow),
 * hides them for a hidden case, lets them settle, then counts for BENCH_VIEWER_SECONDS.
 */
async function runCase(
  c: Case,
  ctxs: BrowserContext[],
  browser: Browser,
  base: string,
  servers: SimServer[],
): Promise<{ measured: Measured[]; onlineTiles: number }> {
  const ids = servers.map((s) => s.id);
  if (ctxs.length > c.viewers) throw new Error(`${c.name}: the cases must not lose viewers`);
  const opened = await Promise.allSettled(
    Array.from({ length: c.viewers - ctxs.length }, () => openViewer(browser, base, ids)),
  );
  for (const o of opened) if (o.status === 'fulfilled') ctxs.push(o.value);
  const failed = opened.find((o) => o.status === 'rejected');
  if (failed) throw failed.reason;
  if (c.hidden) for (const ctx of ctxs) for (const page of ctx.pages()) await hide(page);
  await sleep(WARMUP_MS);
  for (const s of servers) s.resetStats();
  const t0 = performance.now();
  await sleep(SECONDS * 1000);
  const seconds = (performance.now() - t0) / 1000;
  const measured = servers.map((s) => ({ family: s.kind, seconds, stats: s.stats() }));
  return { measured, onlineTiles: await onlineTiles(ctxs) };
}

// ---------------------------------------------------------------- report

interface Rates {
  req: number;
  tcp: number;
}

const perMin = (n: number, seconds: number): number => round((n / seconds) * 60, 1);
const ratio = (a: number, b: number): number | null => (b > 0 ? round(a / b, 2) : null);

function reportCase(c: Case, m: Measured[], tiles: number, one: Map<string, Rates>): void {
  const all: Measured = {
    family: 'all',
    seconds: m[0]?.seconds ?? SECONDS,
    stats: m.reduce<SimServerStats>(
      (a, x) => ({
        requests: a.requests + x.stats.requests,
        connections: a.connections + x.stats.connections,
        wsOpen: a.wsOpen + x.stats.wsOpen,
        wsOpened: a.wsOpened + x.stats.wsOpened,
        wsMaxOpen: a.wsMaxOpen + x.stats.wsMaxOpen,
      }),
      { requests: 0, connections: 0, wsOpen: 0, wsOpened: 0, wsMaxOpen: 0 },
    ),
  };
  for (const x of [...m, all]) {
    const machines = x.family === 'all' ? m.length : 1;
    const req = perMin(x.stats.requests, x.seconds);
    const tcp = perMin(x.stats.connections, x.seconds);
    const base = one.get(x.family);
    const reqRatio = base ? ratio(req, base.req) : null;
    const tcpRatio = base ? ratio(tcp, base.tcp) : null;
    const okRatio = c.viewers === 1 || reqRatio === null || reqRatio <= TARGET_RATIO;
    const okSocket = x.stats.wsMaxOpen <= machines;
    const okTcp = base ? tcp <= base.req : true;
    const misses = [okRatio ? '' : 'req', okTcp ? '' : 'tcp', okSocket ? '' : 'ws'].filter(Boolean);
    report({
      name: `${c.name}: ${x.family}`,
      family: x.family,
      viewers: c.viewers,
      hidden: c.hidden,
      seconds: round(x.seconds, 1),
      req_per_min: req,
      req_x_1: reqRatio,
      target_req_x: c.viewers === 1 ? null : TARGET_RATIO,
      tcp_per_min: tcp,
      tcp_x_1: tcpRatio,
      target_tcp_per_min: base ? base.req : null,
      ws_open_max: x.stats.wsMaxOpen,
      ws_open_end: x.stats.wsOpen,
      target_ws_max: machines,
      ws_opened: x.stats.wsOpened,
      meets: misses.length ? `no: ${misses.join(', ')}` : 'yes',
      ...(x.family === 'all' ? { tiles_online: `${tiles}/${c.viewers * m.length}` } : {}),
    });
  }
}

// ---------------------------------------------------------------- main

async function main(): Promise<void> {
  if (!Number.isFinite(SECONDS) || SECONDS <= 0)
    throw new Error(
      `BENCH_VIEWER_SECONDS must be a positive number, not ${process.env.BENCH_VIEWER_SECONDS}`,
    );
  ensureDist();
  const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-viewers-'));
  let fleet: SimFleet | null = null;
  let server: Server | null = null;
  let browser: Browser | null = null;
  const cleanup = async (): Promise<void> => {
    await browser?.close().catch(() => undefined);
    browser = null;
    await server?.stop().catch(() => undefined);
    server = null;
    await fleet?.close().catch(() => undefined);
    fleet = null;
    rmSync(work, { recursive: true, force: true });
  };
  const unhook = stopOnSignal(cleanup);
  try {
    fleet = await startSimFleet(families);
    const machinesFile = path.join(work, 'machines.json');
    writeFileSync(machinesFile, JSON.stringify(fleet.machinesFile, null, 2));
    server = await startServer(work, machinesFile);
    browser = await launchChromium();
    const servers = fleet.servers;
    log(
      `${servers.length} controllers, server ${server.base}, ${SECONDS} s per case, ` +
        `about ${Math.ceil((CASES.length * (SECONDS + 6)) / 60)} min`,
    );
    const one = new Map<string, Rates>();
    const pending: Array<() => void> = [];
    const ctxs: BrowserContext[] = [];
    for (const c of CASES) {
      const t0 = performance.now();
      log(`${c.name}…`);
      const r = await runCase(c, ctxs, browser, server.base, servers);
      if (c.viewers === 1 && !c.hidden) {
        for (const x of r.measured)
          one.set(x.family, {
            req: perMin(x.stats.requests, x.seconds),
            tcp: perMin(x.stats.connections, x.seconds),
          });
        const sum = (f: (x: Measured) => number): number =>
          perMin(
            r.measured.reduce((a, x) => a + f(x), 0),
            r.measured[0]?.seconds ?? SECONDS,
          );
        one.set('all', { req: sum((x) => x.stats.requests), tcp: sum((x) => x.stats.connections) });
      }
      const print = (): void => reportCase(c, r.measured, r.onlineTiles, one);
      // Ratios need the one-viewer numbers: "no viewer" is printed once they are known.
      if (one.size) {
        for (const p of pending.splice(0)) p();
        print();
      } else pending.push(print);
      log(`${c.name}: ${round((performance.now() - t0) / 1000, 1)} s`);
    }
    for (const p of pending.splice(0)) p();
  } finally {
    unhook();
    await cleanup();
  }
}

main().catch((e: unknown) => {
  log(e instanceof Error ? e.message : String(e));
  process.exit(1);
});
