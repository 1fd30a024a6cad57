/**
 * 100 machines on the fleet page (issue 16): 20 simulated machines per family, answered by the
 * gateway's simulators at their native rates through the production server, the fleet page open
 * in Chromium (1440x900).
 *
 * - Data to DOM: each data age (tile and machine page) carries `data-updated-at`, the page-clock time its machine's data
 *   arrived (the session's `updatedAt`); a MutationObserver in the page notes, when the attribute
 *   changes, how long ago that was. p50/p95/max over the window; target p95 ≤ 50 ms. The gateway's
 *   own added latency (controller to page) is measured by gateway.bench.ts.
 * - Main thread over BENCH_FLEET_SECONDS (default 60) after every tile is Online and 5 s of
 *   settling: busy share (CDP TaskDuration), long tasks (PerformanceObserver 'longtask', > 50 ms),
 *   layouts and style recalculations per second. Targets: no long task, busy ≤ 30 %.
 * - Heap: JS heap after a forced GC at the start of the window and each minute for
 *   BENCH_FLEET_HEAP_MINUTES (default 3; the issue's figure is 15); target growth ≤ 10 MB over
 *   15 minutes (a shorter run says so in its note).
 *
 *     BENCH_FLEET_SECONDS=20 BENCH_FLEET_HEAP_MINUTES=1 npx tsx tests/bench/fleet100.bench.ts
 *
 * - BENCH_FLEET_SNAPSHOTS=<dir> (opt-in): a heap snapshot (forced GC first) at the start of the
 *   heap run and one at its end, written to <dir>/start.heapsnapshot and end.heapsnapshot, and
 *   their comparison (per constructor: count and self size in each, the difference, largest
 *   growth first; the retainer paths of the top growers' new objects) to <dir>/compare.txt
 *   (heap-snapshot.ts; it also compares two files by hand). The samples of a run with snapshots
 *   are not comparable with one without. BENCH_DIST=<dir> serves an unminified build
 *   (`npx vite build --minify false --outDir <dir>`) to see the page's own class names.
 *
 * Needs a built dist/ (built here when missing).
 */
import { mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { type Browser, type CDPSession, type Page } from '@playwright/test';
import { MACHINE_KINDS } from '../../src/controllers';
import { comparisonText, parseSnapshot, takeSnapshot } from './heap-snapshot';
import { launchChromium, stopOnSignal, ensureDist, sleep, startServer, type Server } from './harness';
import { median, report, round } from './util';

const PER_FAMILY = Number(process.env.BENCH_FLEET_PER_FAMILY ?? 20);
const SECONDS = Number(process.env.BENCH_FLEET_SECONDS ?? 60);
const HEAP_MINUTES = Number(process.env.BENCH_FLEET_HEAP_MINUTES ?? 3);
const SETTLE_MS = 5000;
const SNAPSHOTS = process.env.BENCH_FLEET_SNAPSHOTS;

const log = (msg: string): void => {
  process.stderr.write(`fleet100.bench: ${msg}\n`);
};

/** Installed in the page before its scripts: the data-to-DOM observer and the long-task list. */
function instrument(): void {
  const w = window as unknown as { __bench: Bench };
  const long = new PerformanceObserver((list) => {
    for (const e of list.getEntries()) w.__bench.long.push(e.duration);
  });
  long.observe({ type: 'longtask', buffered: true });
  const dom = new MutationObserver((records) => {
    const now = Date.now();
    for (const r of records) {
      const at = Number((r.target as Element).getAttribute('data-updated-at'));
      if (at > 0) w.__bench.lat.push(now - at);
    }
  });
  dom.observe(document, { subtree: true, attributes: true, attributeFilter: ['data-updated-at'] });
  // No function in this object: the bundler would wrap it in a naming helper the page lacks.
  w.__bench = { lat: [], long: [], observers: [long, dom] };
}

/** The page's instrumentation: latencies and long tasks; its observers, stopped before the heap run. */
interface Bench {
  lat: number[];
  long: number[];
  observers: Array<{ disconnect(): void }>;
}

async function metrics(cdp: CDPSession): Promise<Record<string, number>> {
  const { metrics: list } = (await cdp.send('Performance.getMetrics')) as {
    metrics: Array<{ name: string; value: number }>;
  };
  return Object.fromEntries(list.map((m) => [m.name, m.value]));
}

async function heapAfterGc(cdp: CDPSession): Promise<number> {
  await cdp.send('HeapProfiler.collectGarbage');
  const { usedSize } = (await cdp.send('Runtime.getHeapUsage')) as { usedSize: number };
  return usedSize / 2 ** 20;
}

const percentile = (xs: number[], p: number): number => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length ? (s[Math.min(s.length - 1, Math.floor(s.length * p))] as number) : NaN;
};

async function onlineCount(page: Page): Promise<number> {
  return page.evaluate(
    () =>
      [...document.querySelectorAll('article[data-testid^="tile-"] [data-testid="tile-link"]')].filter(
        (e) => e.textContent === 'Online',
      ).length,
  );
}

async function main(): Promise<void> {
  for (const [k, v] of Object.entries({ PER_FAMILY, SECONDS, HEAP_MINUTES }))
    if (!Number.isFinite(v) || v <= 0) throw new Error(`${k} must be a positive number`);
  ensureDist();
  const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-fleet100-'));
  const machines = MACHINE_KINDS.flatMap((kind) =>
    Array.from({ length: PER_FAMILY }, (_, i) => ({
      id: `${kind}-${i + 1}`,
      name: `${kind} ${i + 1}`,
      kind,
      simulated: true,
    })),
  );
  const file = path.join(work, 'machines.json');
  writeFileSync(file, JSON.stringify({ machines }));
  let server: Server | null = null;
  let browser: Browser | null = null;
  const cleanup = async (): Promise<void> => {
    await browser?.close().catch(() => undefined);
    browser = null;
    await server?.stop().catch(() => undefined);
    server = null;
    rmSync(work, { recursive: true, force: true });
  };
  const unhook = stopOnSignal(cleanup);
  try {
    server = await startServer(work, file);
    browser = await launchChromium();
    const ctx = await browser.newContext({ viewport: { width: 1440, height: 900 } });
    await ctx.addInitScript(instrument);
    const page = await ctx.newPage();
    const t0 = Date.now();
    await page.goto(`${server.base}/`);
    let online = 0;
    while (Date.now() - t0 < 120_000) {
      online = await onlineCount(page);
      if (online === machines.length) break;
      await sleep(500);
    }
    const allOnlineS = (Date.now() - t0) / 1000;
    log(`${online}/${machines.length} tiles online after ${allOnlineS.toFixed(1)} s`);
    await sleep(SETTLE_MS);
    const cdp = await ctx.newCDPSession(page);
    await cdp.send('Performance.enable');
    const heap: number[] = [await heapAfterGc(cdp)];
    const heapFrom = Date.now();
    await page.evaluate(() => {
      const b = (window as unknown as { __bench: Bench }).__bench;
      b.lat.length = 0;
      b.long.length = 0;
    });
    const m0 = await metrics(cdp);
    await sleep(SECONDS * 1000);
    const m1 = await metrics(cdp);
    // Read, then stopped: its arrays (about 100 latencies a second) would grow through the heap run.
    const { lat, long } = await page.evaluate(() => {
      const b = (window as unknown as { __bench: Bench }).__bench;
      for (const o of b.observers) o.disconnect();
      const out = { lat: b.lat.slice(), long: b.long.slice() };
      b.lat.length = 0;
      b.long.length = 0;
      return out;
    });
    const span = (m1.Timestamp ?? 0) - (m0.Timestamp ?? 0) || SECONDS;
    const d = (k: string): number => (m1[k] ?? 0) - (m0[k] ?? 0);
    const busy = (d('TaskDuration') / span) * 100;
    const p95 = percentile(lat, 0.95);
    const misses = [
      ...(long.length ? [`${long.length} long tasks`] : []),
      ...(busy > 30 ? [`busy ${round(busy, 1)} %`] : []),
      ...(!(p95 <= 50) ? [`p95 ${p95} ms`] : []),
      ...(online < machines.length ? [`${machines.length - online} tiles not online`] : []),
    ];
    report({
      name: `fleet page: ${machines.length} machines, ${SECONDS} s`,
      tiles_online: `${online}/${machines.length}`,
      all_online_s: round(allOnlineS, 1),
      updates: lat.length,
      updates_per_s: round(lat.length / span, 1),
      data_to_dom_p50_ms: round(median(lat), 1),
      data_to_dom_p95_ms: round(p95, 1),
      data_to_dom_max_ms: round(Math.max(0, ...lat), 1),
      target_data_to_dom_p95_ms: 50,
      busy_pct: round(busy, 1),
      target_busy_pct: 30,
      script_s: round(d('ScriptDuration'), 2),
      long_tasks: long.length,
      longest_task_ms: round(Math.max(0, ...long), 1),
      target_long_tasks: 0,
      layouts_per_s: round(d('LayoutCount') / span, 1),
      style_recalcs_per_s: round(d('RecalcStyleCount') / span, 1),
      meets: misses.length ? `no: ${misses.join(', ')}` : 'yes',
    });
    if (SNAPSHOTS) {
      mkdirSync(SNAPSHOTS, { recursive: true });
      await takeSnapshot(cdp, path.join(SNAPSHOTS, 'start.heapsnapshot'));
      log(`snapshot: ${path.join(SNAPSHOTS, 'start.heapsnapshot')}`);
    }
    // Heap: one sample a minute after a forced GC (the first was taken before the window).
    const heapEnd = Date.now() + HEAP_MINUTES * 60_000;
    let next = Date.now() + 60_000;
    while (Date.now() < heapEnd) {
      await sleep(Math.max(0, Math.min(next, heapEnd) - Date.now()));
      heap.push(await heapAfterGc(cdp));
      next += 60_000;
    }
    if (SNAPSHOTS) {
      const [a, b] = ['start', 'end'].map((n) => path.join(SNAPSHOTS, `${n}.heapsnapshot`)) as [
        string,
        string,
      ];
      await takeSnapshot(cdp, b);
      const text = comparisonText(
        parseSnapshot(readFileSync(a, 'utf8')),
        parseSnapshot(readFileSync(b, 'utf8')),
      );
      writeFileSync(path.join(SNAPSHOTS, 'compare.txt'), text);
      log(
        `snapshots compared: ${path.join(SNAPSHOTS, 'compare.txt')}\n${text.split('\n').slice(0, 25).join('\n')}`,
      );
    }
    const growth = (heap.at(-1) ?? 0) - (heap[0] ?? 0);
    // Stretched to 15 minutes when the run was shorter (linear: a leak grows with time).
    const minutes = (Date.now() - heapFrom) / 60_000;
    const per15 = (growth / minutes) * 15;
    report({
      name: `heap: ${machines.length} machines, ${round(minutes, 1)} min`,
      heap_start_mib: round(heap[0] ?? 0, 1),
      heap_end_mib: round(heap.at(-1) ?? 0, 1),
      heap_max_mib: round(Math.max(...heap), 1),
      growth_mib: round(growth, 2),
      growth_per_15_min_mib: round(per15, 2),
      target_growth_15_min_mib: 10,
      samples_mib: heap.map((h) => round(h, 1)).join(' '),
      meets: per15 <= 10 ? 'yes' : `no: ${round(per15, 1)} MiB per 15 min`,
      ...(HEAP_MINUTES < 15
        ? {
            note: `a ${HEAP_MINUTES}-minute run; growth per 15 min extrapolated linearly (BENCH_FLEET_HEAP_MINUTES=15 for the full run)`,
          }
        : {}),
    });
  } finally {
    unhook();
    await cleanup();
  }
}

main().catch((e: unknown) => {
  process.stderr.write(`${e instanceof Error ? (e.stack ?? e.message) : String(e)}\n`);
  process.exit(1);
});
