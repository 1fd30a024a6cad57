import http from 'node:http';
import path from 'node:path';
import { monitorEventLoopDelay } from 'node:perf_hooks';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { csvRow } from '../../src/ui/csv';
import type { MachineEntry } from '../machines';
import { login, startGateway, tempDir, testFamily, user, writeJson } from '../test-util';
import { openHistoryDb } from './db';
import { HISTORY_FILE } from './index';

/**
 * Finding 8, the attack: a filled history (300,000 state intervals) and eight `states.csv`
 * exports at once, through the real gateway on real sockets. The gateway's thread must stay
 * responsive (its event loop measured in this process, where the gateway runs, and the latency of
 * `GET /api/session` meanwhile), one user gets at most 2 at once (429 beyond), and every export
 * that completes is whole and right.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterAll(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const MACHINES = 10;
const PER_MACHINE = 30_000;
const STEP_MS = 2880; // 30,000 intervals of 2.88 s: one day per machine
const DAY_MS = 86_400_000;
const MAX_ROWS = 50_000; // the states answer's bound (README)
const STATES = ['running', 'paused', 'idle', 'alarm'] as const;
const ids = Array.from({ length: MACHINES }, (_, i) => `m${String(i).padStart(2, '0')}`);
// The machines file in the reverse of the ids' order: the CSV follows the file, the bound the ids.
const machines: MachineEntry[] = [...ids].reverse().map((id) => ({
  id,
  name: `Table ${id}`,
  kind: 'xtool',
  simulated: true,
  url: null,
  wsUrl: null,
  secrets: {},
}));

function fill(file: string, from: number): void {
  const { db } = openHistoryDb(file);
  const ins = db.prepare(
    'INSERT INTO states (machine, state, alarm, started_at, ended_at) VALUES (?, ?, ?, ?, ?)',
  );
  db.transaction(() => {
    for (const id of ids) {
      for (let k = 0; k < PER_MACHINE; k++) {
        const state = STATES[k % STATES.length] ?? 'idle';
        const t = from + k * STEP_MS;
        ins.run(id, state, state === 'alarm' ? `Flame out ${k % 7}` : null, t, t + STEP_MS);
      }
      db.prepare('INSERT INTO last_seen (machine, at) VALUES (?, ?)').run(id, from + DAY_MS);
    }
  })();
  db.close();
}

/** The CSV the export must be, built here from what `fill` wrote: not through the gateway's code. */
function expectedCsv(from: number): string {
  const header = ['machine', 'machine_name', 'state', 'alarm', 'from', 'to', 'seconds', 'open'];
  // The first 50,000 in the order of the ids, then written in the machines file's order.
  const take = new Map<string, number>();
  let left = MAX_ROWS;
  for (const id of ids) {
    const n = Math.min(left, PER_MACHINE);
    take.set(id, n);
    left -= n;
  }
  const lines = [csvRow(header)];
  for (const m of machines) {
    for (let k = 0; k < (take.get(m.id) ?? 0); k++) {
      const state = STATES[k % STATES.length] ?? 'idle';
      const t = from + k * STEP_MS;
      lines.push(
        csvRow([
          m.id,
          m.name,
          state,
          state === 'alarm' ? `Flame out ${k % 7}` : null,
          new Date(t).toISOString(),
          new Date(t + STEP_MS).toISOString(),
          STEP_MS / 1000,
          false,
        ]),
      );
    }
  }
  return `\uFEFF${lines.join('\r\n')}\r\n`;
}

interface Answer {
  status: number;
  headers: http.IncomingHttpHeaders;
  body: string;
}

/** A plain HTTP GET (no fetch: its connection pool would queue the requests we want at once). */
function get(url: string, cookie: string, agent: http.Agent): Promise<Answer> {
  return new Promise((resolve, reject) => {
    const req = http.get(url, { headers: { cookie, 'X-Shopdeck': '1' }, agent }, (res) => {
      const chunks: Buffer[] = [];
      res.on('data', (c: Buffer) => chunks.push(c));
      res.on('end', () =>
        resolve({
          status: res.statusCode ?? 0,
          headers: res.headers,
          body: Buffer.concat(chunks).toString('utf8'),
        }),
      );
      res.on('error', reject);
    });
    req.on('error', reject);
  });
}

async function setup() {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const from = Math.floor((Date.now() - 2 * DAY_MS) / 1000) * 1000;
  fill(path.join(t.dir, HISTORY_FILE), from);
  const usersFile = path.join(t.dir, 'users.json');
  const names = ['sam', 'ann', 'bob', 'cat'];
  writeJson(usersFile, { users: names.map((n) => user(n, 'supervisor', `${n}-pass-1`)) });
  const gw = await startGateway({
    machines: { file: null, machines },
    families: { xtool: testFamily('xtool') },
    dataDir: t.dir,
    usersFile,
    env: {},
  });
  cleanups.push(gw.close);
  const cookies = await Promise.all(names.map((n) => login(gw.url, n, `${n}-pass-1`)));
  const agent = new http.Agent({ keepAlive: false, maxSockets: 64 });
  cleanups.push(() => agent.destroy());
  const exportUrl = `${gw.url}/api/history/states.csv?from=${from}&to=${from + DAY_MS}`;
  return { gw, from, cookies, agent, exportUrl };
}

/** Runs `attack` while measuring this thread's event-loop delay and a small request's latency. */
async function measured<T>(
  base: string,
  cookie: string,
  agent: http.Agent,
  attack: () => Promise<T>,
): Promise<{ result: T; maxDelayMs: number; maxSessionMs: number }> {
  const h = monitorEventLoopDelay({ resolution: 10 });
  h.enable();
  let done = false;
  let maxSessionMs = 0;
  const probe = (async () => {
    while (!done) {
      const t0 = performance.now();
      const r = await get(`${base}/api/session`, cookie, agent);
      expect(r.status).toBe(200);
      maxSessionMs = Math.max(maxSessionMs, performance.now() - t0);
      await new Promise((r) => setTimeout(r, 20));
    }
  })();
  try {
    const result = await attack();
    return { result, maxDelayMs: h.max / 1e6, maxSessionMs };
  } finally {
    done = true;
    h.disable();
    await probe;
  }
}

/** Resolves when `ok()` holds, polling; rejects after `ms`. */
async function until(what: string, ok: () => boolean, ms = 10_000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 20));
  }
}

describe('history exports do not stall the gateway (finding 8)', () => {
  // One filled history and one gateway for the three (the filling is the slow part).
  let s: Awaited<ReturnType<typeof setup>>;
  beforeAll(async () => {
    s = await setup();
  }, 30_000);

  it('eight states.csv at once as one user: 2 run, 6 get 429; the thread stays responsive; each export whole', async () => {
    const { gw, from, cookies, agent, exportUrl } = s;
    const sam = cookies[0] ?? '';
    const { result, maxDelayMs, maxSessionMs } = await measured(gw.url, sam, agent, () =>
      Promise.all(Array.from({ length: 8 }, () => get(exportUrl, sam, agent))),
    );
    const ok = result.filter((r) => r.status === 200);
    const refused = result.filter((r) => r.status === 429);
    expect(ok.length).toBe(2);
    expect(refused.length).toBe(6);
    for (const r of refused) expect(Number(r.headers['retry-after'])).toBeGreaterThan(0);
    const want = expectedCsv(from);
    for (const r of ok) {
      expect(r.headers['content-type']).toBe('text/csv; charset=utf-8');
      // More than the bound: the export says it is cut short (its body is what it always was).
      expect(r.headers['x-shopdeck-truncated']).toBe('true');
      expect(r.body.length).toBe(want.length);
      expect(r.body === want).toBe(true);
    }
    expect(maxDelayMs, 'event-loop delay').toBeLessThan(300);
    expect(maxSessionMs, 'GET /api/session latency').toBeLessThan(500);
  }, 60_000);

  it('eight states.csv at once from four users: all answered whole; the thread stays responsive', async () => {
    const { gw, from, cookies, agent, exportUrl } = s;
    const { result, maxDelayMs, maxSessionMs } = await measured(gw.url, cookies[0] ?? '', agent, () =>
      Promise.all(Array.from({ length: 8 }, (_, i) => get(exportUrl, cookies[i % 4] ?? '', agent))),
    );
    const want = expectedCsv(from);
    for (const r of result) {
      expect(r.status).toBe(200);
      expect(r.body === want).toBe(true);
    }
    expect(maxDelayMs, 'event-loop delay').toBeLessThan(300);
    expect(maxSessionMs, 'GET /api/session latency').toBeLessThan(500);
  }, 60_000);

  it('a client that goes away mid-export cancels its query and frees its place', async () => {
    const { gw, cookies, agent, exportUrl } = s;
    const sam = cookies[0] ?? '';
    const reads = gw.gw.history.reads;
    if (!reads) throw new Error('no history reads');
    // Two exports (the most one user may run), each dropped after its first bytes.
    await Promise.all(
      [0, 1].map(
        () =>
          new Promise<void>((resolve, reject) => {
            const req = http.get(exportUrl, { headers: { cookie: sam, 'X-Shopdeck': '1' }, agent }, (res) => {
              expect(res.statusCode).toBe(200);
              res.once('data', () => {
                req.destroy();
                resolve();
              });
            });
            req.on('error', () => undefined);
            setTimeout(() => reject(new Error('no first bytes')), 20_000);
          }),
      ),
    );
    // Never read on: without the cancel the worker would wait for the client until the stall cut-off (60 s).
    await until('the cancelled exports to end in the worker', () => reads.stats().running === 0);
    const again = await get(`${gw.url}/api/history/utilisation`, sam, agent);
    expect(again.status).toBe(200);
  }, 60_000);
});
