/**
 * Page cost (issue 16 "Fast and light"): what the built console costs a browser to load, and to
 * keep open.
 *
 * The production server (`node --import tsx server/main.ts`, open mode) serves dist/ with a
 * machines file of five simulated machines, one per family (demo-touchcut, demo-g2core,
 * demo-duet, demo-xtool, demo-prunt); each simulator's "demo" control is started through the
 * simulator API (`POST /api/sim/<id>`, gateway/sim-api.ts) so the machines run jobs.
 *
 * Load: the fleet page `/`, a kiosk tablet's page `/m/demo-xtool?kiosk` and the machine page
 * `/m/demo-xtool`, BENCH_LOAD_ROUNDS (default 13) interleaved rounds, each in a fresh Chromium
 * context (empty cache). Per round: the load event (navigation entry's loadEventEnd, from
 * navigation start); the first screen (fleet: every tile shows a state; kiosk: its machine shows
 * a state; both from the console server's reading in the machines list before the family's code,
 * src/app/first-screen.ts); when the page shows its data live (fleet: every tile's `tile-link`
 * reads Online; kiosk: `kiosk-link` reads Online; machine page: `machine-link` reads Online and
 * `.tab-body` shows something other than `view-loading`); and the JS+CSS resources finished by
 * each. Bytes: `encodedBodySize` (what went on the wire: brotli, as Chromium accepts br) and the
 * gzip size of the same files (dist/assets/<file>.gz; files under the precompression threshold
 * have no .gz and are served as they are, so their own size).
 * Targets: JS+CSS gzip by the first screen ≤ 150 KiB (fleet) / 120 KiB (kiosk); load event
 * ≤ 0.5 × Fluidd's 2805 ms and ≤ 1.5 × Prunt's own UI 595 ms (the reference run).
 *
 * Idle: the fleet page open at 1440×900 with the five machines; after 5 s of settling,
 * BENCH_IDLE_SECONDS (default 60) measured through CDP `Performance.getMetrics` (sampled every
 * few seconds: medians/p95 are over those intervals, totals over the window): main-thread busy %
 * (TaskDuration), script/layout/style-recalc shares, LayoutCount and RecalcStyleCount per second; the running
 * animations (`document.getAnimations()`, the properties their keyframes animate). Then the same
 * with the page hidden (visibilityState overridden and `visibilitychange` dispatched, as in
 * viewers.bench.ts: headless Chromium never hides a page, so frames and timers are not
 * throttled as in a real background tab). Targets: busy ≤ 2 %, layouts/s < 1, animations on
 * transform/opacity only. After each window, 5 s of DOM mutation counting (outside the window:
 * an observer would perturb it) say how often the page changes.
 *
 * `BENCH_LOAD_ROUNDS=3 BENCH_IDLE_SECONDS=10 node --expose-gc --import tsx tests/bench/page.bench.ts`
 * for a quick run; `npm run bench -- page` for the report. Needs a built dist/ (built when missing).
 */
import { existsSync, mkdtempSync, rmSync, statSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { type Browser, type CDPSession, type Page } from '@playwright/test';
import {
  launchChromium,
  stopOnSignal,
  distDir,
  ensureDist,
  sleep,
  startServer,
  type Server,
} from './harness';
import { median, report, round } from './util';

const LOAD_ROUNDS = Number(process.env.BENCH_LOAD_ROUNDS ?? 13);
const IDLE_SECONDS = Number(process.env.BENCH_IDLE_SECONDS ?? 60);
const SETTLE_MS = 5000;
const MUTATION_MS = 5000;
const SHOWN_TIMEOUT_MS = 30_000;
const VIEWPORT = { width: 1440, height: 900 };

const REFERENCE_FLUIDD_MS = 2805;
const REFERENCE_PRUNT_MS = 595;
const TARGET_FLUIDD_RATIO = 0.5;
const TARGET_PRUNT_RATIO = 1.5;
const TARGET_LOAD_FLUIDD_MS = Math.floor(TARGET_FLUIDD_RATIO * REFERENCE_FLUIDD_MS); // 1402
const TARGET_LOAD_PRUNT_MS = Math.floor(TARGET_PRUNT_RATIO * REFERENCE_PRUNT_MS); // 892
const TARGET_BUSY_PCT = 2;
/**
 * "No layout per frame" (the baseline laid out on all 59 frames a second, an animation of
 * a layout property): layouts only where the content changes, at most one frame in ten at 60 Hz.
 */
const TARGET_LAYOUTS_PER_S = 6;
const CHEAP_PROPERTIES = new Set(['transform', 'opacity']);

const MACHINES = [
  { id: 'demo-touchcut', name: 'Demo TouchCut', kind: 'touchcut', simulated: true },
  { id: 'demo-g2core', name: 'Demo g2core', kind: 'g2core', simulated: true },
  { id: 'demo-duet', name: 'Demo Duet', kind: 'duet', simulated: true },
  { id: 'demo-xtool', name: 'Demo xTool', kind: 'xtool', simulated: true },
  { id: 'demo-prunt', name: 'Demo Prunt', kind: 'prunt', simulated: true },
] as const;
const IDS = MACHINES.map((m) => m.id);

const log = (msg: string): void => {
  process.stderr.write(`page.bench: ${msg}\n`);
};

const kib = (bytes: number): number => round(bytes / 1024, 1);

function p95(xs: number[]): number {
  const s = [...xs].sort((a, b) => a - b);
  return s[Math.max(0, Math.ceil(s.length * 0.95) - 1)] ?? 0;
}

// ---------------------------------------------------------------- in-page expressions
// Strings, not functions: tsx would wrap a function's inner arrows in a helper the page lacks.

/** performance.now() once every tile's link reads Online, else false. */
const FLEET_SHOWN = `(() => {
  const ids = ${JSON.stringify(IDS)};
  const ok = ids.every((id) => {
    const l = document.querySelector('[data-testid="tile-' + id + '"] [data-testid="tile-link"]');
    return !!l && (l.textContent || '').includes('Online');
  });
  return ok ? performance.now() : false;
})()`;

/** performance.now() once the machine's link reads Online and its tab shows more than "Loading…". */
/**
 * The fleet page's first screen: every tile shows a state (from the console server's reading in
 * the machines list, or already from its session), before the families' code is there.
 */
const FLEET_FIRST = `(() => {
  const ids = ${JSON.stringify(IDS)};
  const ok = ids.every((id) => {
    const t = document.querySelector('[data-testid="tile-' + id + '"]');
    return !!t && t.getAttribute('data-activity') !== 'unknown';
  });
  return ok ? performance.now() : false;
})()`;

/**
 * A kiosk tablet's first screen: its machine's state (from the console server's reading in the
 * machines list, or already from its session), before the family's code is there.
 */
const KIOSK_FIRST = `(() => {
  const k = document.querySelector('.kiosk-page');
  return !!k && k.getAttribute('data-activity') !== 'unknown' ? performance.now() : false;
})()`;

/** Where `firstScreenWatcher` leaves the first screen's time (performance.now()), once it shows. */
const FIRST_SEEN = `(window.__shopdeckFirstScreen ?? false)`;

/** An init script: checks `cond` on every DOM change and keeps its first non-false value. */
function firstScreenWatcher(cond: string): string {
  return `(() => {
  const seen = new MutationObserver(() => {
    const v = ${cond};
    if (v === false) return;
    window.__shopdeckFirstScreen = v;
    seen.disconnect();
  });
  seen.observe(document, { subtree: true, childList: true, attributes: true, attributeFilter: ['data-activity'] });
})()`;
}

/** A kiosk tablet's page shows its machine online. */
const KIOSK_SHOWN = `(() => {
  const l = document.querySelector('[data-testid="kiosk-link"]');
  return !!l && (l.textContent || '').includes('Online') ? performance.now() : false;
})()`;

const MACHINE_SHOWN = `(() => {
  const l = document.querySelector('[data-testid="machine-link"]');
  const b = document.querySelector('.tab-body');
  if (!l || !b || !(l.textContent || '').includes('Online')) return false;
  if (!b.firstElementChild || b.querySelector('[data-testid="view-loading"]')) return false;
  return performance.now();
})()`;

const LOAD_DONE = `(() => {
  const n = performance.getEntriesByType('navigation')[0];
  return !!n && n.loadEventEnd > 0;
})()`;

const TIMING = `(() => {
  const n = performance.getEntriesByType('navigation')[0];
  return {
    loadEventEnd: n ? n.loadEventEnd : -1,
    resources: performance.getEntriesByType('resource').map((r) => ({
      name: r.name,
      encodedBodySize: r.encodedBodySize,
      responseEnd: r.responseEnd,
    })),
  };
})()`;

const ANIMATIONS = `document.getAnimations().map((a) => {
  const e = a.effect;
  const kf = e && typeof e.getKeyframes === 'function' ? e.getKeyframes() : [];
  const skip = ['offset', 'computedOffset', 'easing', 'composite'];
  const props = [...new Set(kf.flatMap((k) => Object.keys(k).filter((p) => !skip.includes(p))))];
  const t = e && e.target;
  return {
    type: a.constructor.name,
    name: a.animationName || a.transitionProperty || a.id || '',
    props,
    playState: a.playState,
    target: t
      ? [
          (t.closest('[data-testid^="tile-"]') || { getAttribute: () => '' }).getAttribute('data-testid'),
          t.parentElement ? String(t.parentElement.className) : '',
          t.tagName.toLowerCase(),
        ].filter(Boolean).join(' > ')
      : '',
  };
})`;

const ACTIVITIES = `Object.fromEntries(
  Array.from(document.querySelectorAll('article[data-activity]')).map((e) => [
    (e.getAttribute('data-testid') || '').replace(/^tile-/, ''),
    e.getAttribute('data-activity'),
  ]),
)`;

/**
 * Waits in the page until `cond` (an expression) is not false and returns its value. In the page,
 * not `page.waitForFunction`: the console's CSP forbids the eval that a string predicate needs.
 */
async function waitIn(
  page: Page,
  cond: string,
  poll: 'raf' | number,
  timeoutMs = SHOWN_TIMEOUT_MS,
): Promise<unknown> {
  const next = poll === 'raf' ? 'requestAnimationFrame(tick)' : `setTimeout(tick, ${poll})`;
  return page.evaluate(`new Promise((resolve, reject) => {
    const t0 = performance.now();
    const tick = () => {
      const v = ${cond};
      if (v !== false) return resolve(v);
      if (performance.now() - t0 > ${timeoutMs}) return reject(new Error('timed out after ${timeoutMs} ms: ' + ${JSON.stringify(cond.slice(0, 80))}));
      ${next};
    };
    tick();
  })`);
}

const HIDE = `(() => {
  Object.defineProperty(document, 'visibilityState', { configurable: true, get() { return 'hidden'; } });
  Object.defineProperty(document, 'hidden', { configurable: true, get() { return true; } });
  document.dispatchEvent(new Event('visibilitychange'));
  return document.visibilityState;
})()`;

/** Counts MutationObserver callbacks and mutation records over `ms`. */
const countMutations = (ms: number): string => `new Promise((resolve) => {
  let batches = 0;
  let records = 0;
  const o = new MutationObserver((list) => { batches++; records += list.length; });
  o.observe(document.body, { subtree: true, childList: true, characterData: true, attributes: true });
  setTimeout(() => { o.disconnect(); resolve({ batches, records }); }, ${ms});
})`;

// ---------------------------------------------------------------- load

interface Timing {
  loadEventEnd: number;
  resources: Array<{ name: string; encodedBodySize: number; responseEnd: number }>;
}

interface Bytes {
  files: number;
  br: number;
  gzip: number;
  list: string[];
}

interface Round {
  loadMs: number;
  shownMs: number;
  /** When the first screen showed (the fleet page: every tile with a state); else `shownMs`. */
  firstMs: number;
  beforeLoad: Bytes;
  byData: Bytes;
  byFirst: Bytes;
  encodings: Record<string, number>;
}

const gzipCache = new Map<string, number | null>();

/** Gzip bytes of a built asset: its .gz copy, or the file itself when it has none (served as is). */
function gzipBytes(file: string): number | null {
  let n = gzipCache.get(file);
  if (n !== undefined) return n;
  const p = path.join(distDir, 'assets', file);
  n = existsSync(`${p}.gz`) ? statSync(`${p}.gz`).size : existsSync(p) ? statSync(p).size : null;
  gzipCache.set(file, n);
  return n;
}

const isJsCss = (url: string): boolean => /\.(?:m?js|css)$/i.test(new URL(url).pathname);

function bytesUntil(t: Timing, until: number, missing: Set<string>): Bytes {
  const seen = new Set<string>();
  const out: Bytes = { files: 0, br: 0, gzip: 0, list: [] };
  for (const r of t.resources) {
    if (!isJsCss(r.name) || r.responseEnd > until || seen.has(r.name)) continue;
    seen.add(r.name);
    const file = path.basename(new URL(r.name).pathname);
    const gz = gzipBytes(file);
    if (gz === null) missing.add(file);
    out.files++;
    out.br += r.encodedBodySize;
    out.gzip += gz ?? r.encodedBodySize;
    out.list.push(`${file} ${kib(gz ?? r.encodedBodySize)}`);
  }
  out.list.sort();
  return out;
}

async function loadRound(
  browser: Browser,
  base: string,
  url: string,
  shown: string,
  first: string | null,
  missing: Set<string>,
): Promise<Round> {
  const ctx = await browser.newContext({ viewport: VIEWPORT });
  try {
    const page = await ctx.newPage();
    const encodings: Record<string, number> = {};
    page.on('response', (r) => {
      if (!isJsCss(r.url())) return;
      const enc = r.headers()['content-encoding'] ?? 'identity';
      encodings[enc] = (encodings[enc] ?? 0) + 1;
    });
    // The first screen's time is taken when the DOM changes to it (a mutation observer set up
    // before the page's own scripts), not at the next poll: the family code that starts loading
    // right after a kiosk's first screen is not counted in it.
    if (first !== null) await page.addInitScript(firstScreenWatcher(first));
    await page.goto(`${base}${url}`, { waitUntil: 'commit' });
    const firstMs = first === null ? null : Number(await waitIn(page, FIRST_SEEN, 'raf'));
    const shownMs = Number(await waitIn(page, shown, 'raf'));
    await waitIn(page, LOAD_DONE, 20);
    const t = (await page.evaluate(TIMING)) as Timing;
    return {
      loadMs: t.loadEventEnd,
      shownMs,
      firstMs: firstMs ?? shownMs,
      beforeLoad: bytesUntil(t, t.loadEventEnd, missing),
      byData: bytesUntil(t, shownMs, missing),
      byFirst: bytesUntil(t, firstMs ?? shownMs, missing),
      encodings,
    };
  } finally {
    await ctx.close();
  }
}

function reportLoad(
  name: string,
  url: string,
  rounds: Round[],
  targetKiB: number | null,
  missing: Set<string>,
): void {
  const load = rounds.map((r) => r.loadMs);
  const shown = rounds.map((r) => r.shownMs);
  const stat = (f: (r: Round) => number): { median: number; min: number; max: number } => {
    const xs = rounds.map(f);
    return { median: median(xs), min: Math.min(...xs), max: Math.max(...xs) };
  };
  const blGz = stat((r) => r.beforeLoad.gzip);
  const blBr = stat((r) => r.beforeLoad.br);
  const bdGz = stat((r) => r.byData.gzip);
  const bdBr = stat((r) => r.byData.br);
  const bfGz = stat((r) => r.byFirst.gzip);
  const loadMed = median(load);
  const encodings: Record<string, number> = {};
  for (const r of rounds)
    for (const [k, v] of Object.entries(r.encodings)) encodings[k] = (encodings[k] ?? 0) + v;
  // The round whose by-data bytes are the median (its file list).
  const mid = [...rounds].sort((a, b) => a.byData.gzip - b.byData.gzip)[Math.floor(rounds.length / 2)];
  const misses: string[] = [];
  // The size target is the first screen's: what is loaded when it shows (and before the load event).
  if (targetKiB !== null && kib(bfGz.median) > targetKiB)
    misses.push(`first-screen JS+CSS ${kib(bfGz.median)} KiB gzip > ${targetKiB}`);
  if (targetKiB !== null && kib(blGz.median) > targetKiB)
    misses.push(`before-load JS+CSS ${kib(blGz.median)} KiB gzip > ${targetKiB}`);
  if (loadMed > TARGET_LOAD_FLUIDD_MS)
    misses.push(`load ${round(loadMed, 0)} ms > ${TARGET_LOAD_FLUIDD_MS} (Fluidd)`);
  if (loadMed > TARGET_LOAD_PRUNT_MS)
    misses.push(`load ${round(loadMed, 0)} ms > ${TARGET_LOAD_PRUNT_MS} (Prunt)`);
  report({
    name,
    url,
    rounds: rounds.length,
    load_event_ms: round(loadMed, 1),
    load_event_p95_ms: round(p95(load), 1),
    reference_fluidd_ms: REFERENCE_FLUIDD_MS,
    ratio_to_fluidd: round(loadMed / REFERENCE_FLUIDD_MS, 3),
    target_ratio_to_fluidd: TARGET_FLUIDD_RATIO,
    target_load_fluidd_ms: TARGET_LOAD_FLUIDD_MS,
    reference_prunt_ms: REFERENCE_PRUNT_MS,
    ratio_to_prunt: round(loadMed / REFERENCE_PRUNT_MS, 3),
    target_ratio_to_prunt: TARGET_PRUNT_RATIO,
    target_load_prunt_ms: TARGET_LOAD_PRUNT_MS,
    first_screen_ms: round(median(rounds.map((r) => r.firstMs)), 1),
    first_screen_js_css_gzip_kib: kib(bfGz.median),
    data_shown_ms: round(median(shown), 1),
    data_shown_p95_ms: round(p95(shown), 1),
    before_load_js_css_gzip_kib: kib(blGz.median),
    before_load_js_css_wire_kib: kib(blBr.median),
    before_load_files: median(rounds.map((r) => r.beforeLoad.files)),
    by_data_js_css_gzip_kib: kib(bdGz.median),
    by_data_js_css_gzip_range_kib: [kib(bdGz.min), kib(bdGz.max)],
    by_data_js_css_wire_kib: kib(bdBr.median),
    by_data_files: median(rounds.map((r) => r.byData.files)),
    target_js_css_gzip_kib: targetKiB ?? '—',
    wire_encodings: encodings,
    ...(missing.size ? { not_in_dist: [...missing] } : {}),
    by_data_chunks_gzip_kib: mid?.byData.list ?? [],
    meets: misses.length ? `no: ${misses.join('; ')}` : 'yes',
  });
}

// ---------------------------------------------------------------- idle

type Metrics = Map<string, number>;

async function metrics(cdp: CDPSession): Promise<Metrics> {
  const r = await cdp.send('Performance.getMetrics');
  return new Map(r.metrics.map((m) => [m.name, m.value]));
}

interface Anim {
  type: string;
  name: string;
  props: string[];
  playState: string;
  target: string;
}

interface Interval {
  seconds: number;
  busyPct: number;
  scriptPct: number;
  layoutPct: number;
  recalcPct: number;
  layoutsPerS: number;
  recalcsPerS: number;
}

function delta(a: Metrics, b: Metrics): Interval {
  const d = (k: string): number => (b.get(k) ?? 0) - (a.get(k) ?? 0);
  const seconds = d('Timestamp');
  return {
    seconds,
    busyPct: (d('TaskDuration') / seconds) * 100,
    scriptPct: (d('ScriptDuration') / seconds) * 100,
    layoutPct: (d('LayoutDuration') / seconds) * 100,
    recalcPct: (d('RecalcStyleDuration') / seconds) * 100,
    layoutsPerS: d('LayoutCount') / seconds,
    recalcsPerS: d('RecalcStyleCount') / seconds,
  };
}

async function idleWindow(page: Page, cdp: CDPSession, name: string, hidden: boolean): Promise<void> {
  await sleep(SETTLE_MS);
  const activitiesStart = (await page.evaluate(ACTIVITIES)) as Record<string, string>;
  const step = Math.max(1, Math.min(5, IDLE_SECONDS / 6));
  const anims = new Map<string, Anim & { samples: number; maxAtOnce: number }>();
  const sampleAnims = async (): Promise<void> => {
    const list = (await page.evaluate(ANIMATIONS)) as Anim[];
    const here = new Map<string, number>();
    for (const a of list) {
      const key = `${a.type}|${a.name}|${a.props.join(',')}|${a.target}`;
      here.set(key, (here.get(key) ?? 0) + 1);
      const x = anims.get(key) ?? { ...a, samples: 0, maxAtOnce: 0 };
      anims.set(key, x);
    }
    for (const [key, n] of here) {
      const x = anims.get(key);
      if (!x) continue;
      x.samples++;
      x.maxAtOnce = Math.max(x.maxAtOnce, n);
    }
  };
  const first = await metrics(cdp);
  let prev = first;
  const intervals: Interval[] = [];
  const t0 = performance.now();
  let samples = 0;
  while (performance.now() - t0 < IDLE_SECONDS * 1000) {
    await sleep(Math.min(step * 1000, IDLE_SECONDS * 1000 - (performance.now() - t0)));
    const m = await metrics(cdp);
    intervals.push(delta(prev, m));
    prev = m;
    await sampleAnims();
    samples++;
  }
  const total = delta(first, prev);
  const activitiesEnd = (await page.evaluate(ACTIVITIES)) as Record<string, string>;
  const mutations = (await page.evaluate(countMutations(MUTATION_MS))) as {
    batches: number;
    records: number;
  };
  const animations = [...anims.values()].map((a) => ({
    type: a.type,
    name: a.name,
    props: a.props,
    target: a.target,
    seen_in_samples: `${a.samples}/${samples}`,
    max_at_once: a.maxAtOnce,
  }));
  const badAnims = animations.filter((a) => a.props.some((p) => !CHEAP_PROPERTIES.has(p)));
  const running = (acts: Record<string, string>): number =>
    Object.values(acts).filter((a) => a === 'running').length;
  const misses: string[] = [];
  if (total.busyPct > TARGET_BUSY_PCT) misses.push(`busy ${round(total.busyPct, 2)} % > ${TARGET_BUSY_PCT}`);
  if (total.layoutsPerS >= TARGET_LAYOUTS_PER_S)
    misses.push(`layouts ${round(total.layoutsPerS, 2)}/s ≥ ${TARGET_LAYOUTS_PER_S}`);
  if (badAnims.length)
    misses.push(`animations on ${[...new Set(badAnims.flatMap((a) => a.props))].join(', ')}`);
  const col = (f: (i: Interval) => number): { median: number; p95: number } => ({
    median: round(median(intervals.map(f)), 3),
    p95: round(p95(intervals.map(f)), 3),
  });
  const busy = col((i) => i.busyPct);
  const layouts = col((i) => i.layoutsPerS);
  const recalcs = col((i) => i.recalcsPerS);
  const mutationBatchesPerS = round(mutations.batches / (MUTATION_MS / 1000), 2);
  const notes: string[] = [];
  if (total.layoutsPerS >= TARGET_LAYOUTS_PER_S)
    notes.push(
      `${round(total.layoutsPerS, 2)} layouts/s is ${round(total.layoutsPerS / 60, 3)} per frame at 60 Hz: ` +
        `the page lays out when its text changes (${mutationBatchesPerS} DOM mutation batches/s measured after ` +
        'the window): tiles re-render at the data rate (progress %, time left, labels; the data-age label ' +
        'reads "live" while answers come, src/app/Age.tsx, and ticks only when they are late)',
    );
  if (total.busyPct > TARGET_BUSY_PCT)
    notes.push(
      `busy ${round(total.busyPct, 1)} %: script ${round(total.scriptPct, 1)} %, layout ${round(total.layoutPct, 1)} %, ` +
        `style ${round(total.recalcPct, 1)} %, the rest (frames: paint and commit; network answers; GC; tasks ` +
        'waiting for a CPU when the machine is loaded) ' +
        `${round(Math.max(0, total.busyPct - total.scriptPct - total.layoutPct - total.recalcPct), 1)} %`,
    );
  if (hidden)
    notes.push(
      'hidden is simulated (visibilityState override + visibilitychange): Chromium keeps producing frames ' +
        'and does not throttle timers as for a real background tab, so this is an upper bound',
    );
  report({
    name,
    viewport: `${VIEWPORT.width}x${VIEWPORT.height}`,
    hidden,
    seconds: round(total.seconds, 1),
    interval_s: round(step, 1),
    busy_pct: round(total.busyPct, 3),
    busy_pct_median: busy.median,
    busy_pct_p95: busy.p95,
    target_busy_pct: TARGET_BUSY_PCT,
    script_pct: round(total.scriptPct, 3),
    layout_pct: round(total.layoutPct, 3),
    recalc_style_pct: round(total.recalcPct, 3),
    other_pct: round(Math.max(0, total.busyPct - total.scriptPct - total.layoutPct - total.recalcPct), 3),
    layouts_per_s: round(total.layoutsPerS, 3),
    layouts_per_s_median: layouts.median,
    layouts_per_s_p95: layouts.p95,
    target_layouts_per_s: TARGET_LAYOUTS_PER_S,
    layouts_per_frame_60hz: round(total.layoutsPerS / 60, 4),
    recalc_styles_per_s: round(total.recalcsPerS, 3),
    recalc_styles_per_s_median: recalcs.median,
    recalc_styles_per_s_p95: recalcs.p95,
    dom_mutation_batches_per_s: mutationBatchesPerS,
    dom_mutation_records_per_s: round(mutations.records / (MUTATION_MS / 1000), 2),
    running_start: `${running(activitiesStart)}/${IDS.length}`,
    running_end: `${running(activitiesEnd)}/${IDS.length}`,
    activities_end: activitiesEnd,
    animations,
    target_animation_props: [...CHEAP_PROPERTIES],
    meets: misses.length ? `no: ${misses.join('; ')}` : 'yes',
    ...(notes.length ? { note: notes.join('. ') } : {}),
  });
}

/** Starts each simulator's demo loop (`world/demo`), as its Simulator tab would. */
async function startDemoJobs(base: string): Promise<void> {
  for (const id of IDS) {
    const r = await fetch(`${base}/api/sim/${id}`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1' },
      body: JSON.stringify({ group: 'world', id: 'demo' }),
    });
    if (!r.ok) log(`${id}: the demo job did not start (HTTP ${r.status}: ${(await r.text()).slice(0, 200)})`);
  }
}

async function idle(browser: Browser, base: string): Promise<void> {
  const ctx = await browser.newContext({ viewport: VIEWPORT });
  try {
    const page = await ctx.newPage();
    await page.goto(`${base}/`);
    await waitIn(page, FLEET_SHOWN, 100);
    // Wait (a while) for a job to run: the xTool demo waits for its simulated button press.
    await waitIn(page, `(Object.values(${ACTIVITIES}).includes('running') || false)`, 200, 20_000).catch(() =>
      log('no machine reads Running: measuring anyway'),
    );
    const cdp = await ctx.newCDPSession(page);
    await cdp.send('Performance.enable');
    log(`idle, visible: ${IDLE_SECONDS} s…`);
    await idleWindow(page, cdp, 'idle: fleet page visible', false);
    const state: unknown = await page.evaluate(HIDE);
    if (state !== 'hidden') throw new Error(`could not hide the page (visibilityState ${String(state)})`);
    log(`idle, hidden: ${IDLE_SECONDS} s…`);
    await idleWindow(page, cdp, 'idle: fleet page hidden', true);
    await cdp.detach();
  } finally {
    await ctx.close();
  }
}

// ---------------------------------------------------------------- main

async function main(): Promise<void> {
  if (!Number.isInteger(LOAD_ROUNDS) || LOAD_ROUNDS <= 0)
    throw new Error(`BENCH_LOAD_ROUNDS must be a positive integer, not ${process.env.BENCH_LOAD_ROUNDS}`);
  if (!Number.isFinite(IDLE_SECONDS) || IDLE_SECONDS <= 0)
    throw new Error(`BENCH_IDLE_SECONDS must be a positive number, not ${process.env.BENCH_IDLE_SECONDS}`);
  ensureDist();
  const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-page-'));
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
    const machinesFile = path.join(work, 'machines.json');
    writeFileSync(machinesFile, JSON.stringify({ machines: MACHINES }, null, 2));
    server = await startServer(work, machinesFile);
    await startDemoJobs(server.base);
    browser = await launchChromium();
    log(`server ${server.base}, ${LOAD_ROUNDS} load rounds, ${IDLE_SECONDS} s idle windows`);
    const pages = [
      // The fleet page: its first screen (tiles from the server's readings) against 150 KiB, then
      // every tile live (the families' code, loaded at idle after the first screen).
      {
        name: 'load: fleet page',
        url: '/',
        shown: FLEET_SHOWN,
        first: FLEET_FIRST as string | null,
        targetKiB: 150 as number | null,
        rounds: [] as Round[],
      },
      // A kiosk tablet's first screen (its machine from the server's reading) against 120 KiB, then
      // live with its controls; the full machine page (its first tab) beside it.
      {
        name: 'load: kiosk page (xtool)',
        url: '/m/demo-xtool?kiosk',
        shown: KIOSK_SHOWN,
        first: KIOSK_FIRST,
        targetKiB: 120,
        rounds: [] as Round[],
      },
      {
        name: 'load: machine page (xtool)',
        url: '/m/demo-xtool',
        shown: MACHINE_SHOWN,
        first: null,
        targetKiB: null,
        rounds: [] as Round[],
      },
    ];
    const missing = new Set<string>();
    for (let i = 0; i < LOAD_ROUNDS; i++) {
      for (const p of pages)
        p.rounds.push(await loadRound(browser, server.base, p.url, p.shown, p.first, missing));
      log(`load round ${i + 1}/${LOAD_ROUNDS}`);
    }
    for (const p of pages) reportLoad(p.name, p.url, p.rounds, p.targetKiB, missing);
    await idle(browser, server.base);
  } finally {
    unhook();
    await cleanup();
  }
}

main().catch((e: unknown) => {
  log(e instanceof Error ? e.message : String(e));
  process.exit(1);
});
