import { mkdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import type { WatchSummary } from '../../src/fleet/contract';
import type { MachineEntry } from '../machines';
import {
  consoleFetch,
  login,
  startGateway,
  tempDir,
  testAccess,
  testFamily,
  user,
  writeJson,
} from '../test-util';
import { S } from './summary.test-util';
import { families } from '../../src/controllers/families';

/** `/api/history/*` through the real gateway: who sees what, CSV safety, settings, a missing store. */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const entry = (id: string, name: string): MachineEntry => ({
  id,
  name,
  kind: 'xtool',
  simulated: true,
  url: null,
  wsUrl: null,
  secrets: {},
});

async function setup(o: { brokenFile?: boolean } = {}) {
  const t = tempDir();
  cleanups.push(t.cleanup);
  if (o.brokenFile) mkdirSync(path.join(t.dir, 'history.sqlite')); // a folder where the file should be
  const usersFile = path.join(t.dir, 'users.json');
  writeJson(usersFile, {
    users: [
      user('sam', 'supervisor', 'sam-pass-1'),
      user('vera', 'viewer', 'vera-pass-1'),
      user('otto', 'operator', 'otto-pass-1', { machines: ['a1'] }),
    ],
  });
  const machines = [entry('a1', 'Laser one'), entry('a2', 'Laser two')];
  const gw = await startGateway({
    machines: { file: null, machines },
    // The test family's job commands, named as the xTool family names them (its access rule's id).
    families: {
      xtool: {
        ...testFamily('xtool'),
        jobs: families.xtool.jobs,
        access: (r) => {
          const d = testAccess(r);
          return d.id ? { ...d, id: d.id.replace(/^test\./, 'xtool.') } : d;
        },
      },
      // Its stored days' route (`/api/history/touchcut-stats`) is the TouchCut server part's.
      touchcut: families.touchcut,
    },
    dataDir: t.dir,
    usersFile,
    env: {},
  });
  cleanups.push(gw.close);
  const feed = (id: string, steps: WatchSummary[]): void => {
    const m = machines.find((x) => x.id === id);
    if (!m) throw new Error(id);
    let prev = S('unknown');
    for (const next of steps) {
      gw.gw.history.observe(m, prev, next);
      prev = next;
    }
  };
  const get = async (cookie: string | null, p: string) => {
    const r = await consoleFetch(`${gw.url}${p}`, { headers: cookie ? { cookie } : {} });
    return { status: r.status, text: await r.text(), type: r.headers.get('content-type') ?? '' };
  };
  const json = async <T>(cookie: string, p: string): Promise<T> => {
    const r = await get(cookie, p);
    expect(r.status, `${p}: ${r.text}`).toBe(200);
    return JSON.parse(r.text) as T;
  };
  return { gw, dir: t.dir, feed, get, json };
}

const ROUTES = [
  '/api/history/jobs',
  '/api/history/jobs.csv',
  '/api/history/states',
  '/api/history/utilisation',
  '/api/history/stops.csv',
  '/api/history/shift-report?shift=Early',
  '/api/history/touchcut-stats',
  '/api/history/info',
];

describe('/api/history: access', () => {
  it('nobody logged in: 401 everywhere', async () => {
    const { get } = await setup();
    for (const r of ROUTES) expect((await get(null, r)).status, r).toBe(401);
  });

  it('an operator limited to one machine sees only it; a viewer and a supervisor see all', async () => {
    const { gw, feed, get, json } = await setup();
    feed('a1', [S('idle'), S('running', { job: 'mine.nc' }), S('alarm', { alarm: 'Flame on a1' })]);
    feed('a2', [S('idle'), S('running', { job: 'secret-customer.nc' }), S('alarm', { alarm: 'Tilt on a2' })]);
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const vera = await login(gw.url, 'vera', 'vera-pass-1');
    const sam = await login(gw.url, 'sam', 'sam-pass-1');

    type Jobs = { jobs: Array<{ machine: string; name: string }>; total: number };
    type PerMachine = { machines: Array<{ machine: string }> };
    const jobs = await json<Jobs>(otto, '/api/history/jobs');
    expect(jobs).toMatchObject({ total: 1, jobs: [{ machine: 'a1', name: 'mine.nc' }] });
    for (const p of [
      '/api/history/states',
      '/api/history/utilisation',
      '/api/history/shift-report?shift=Early',
    ])
      expect(
        (await json<PerMachine>(otto, p)).machines.map((m) => m.machine),
        p,
      ).toEqual(['a1']);
    const stops = await json<{ stops: Array<{ alarm: string }> }>(otto, '/api/history/stops');
    expect(stops.stops.map((s) => s.alarm)).toEqual(['Flame on a1']);
    for (const p of [
      'jobs.csv',
      'states.csv',
      'utilisation.csv',
      'stops.csv',
      'shift-report.csv?shift=Early',
    ]) {
      const csv = await get(otto, `/api/history/${p}`);
      expect(csv.status, p).toBe(200);
      expect(csv.text, p).not.toMatch(/a2|secret-customer|Tilt/);
    }
    // Asking for the other machine by name: as if it did not exist.
    for (const p of ['jobs', 'states', 'utilisation', 'stops', 'touchcut-stats'])
      expect((await get(otto, `/api/history/${p}?machine=a2`)).status, p).toBe(404);

    for (const who of [vera, sam]) {
      expect((await json<Jobs>(who, '/api/history/jobs')).jobs.map((j) => j.machine).sort()).toEqual([
        'a1',
        'a2',
      ]);
      expect((await json<PerMachine>(who, '/api/history/states')).machines.map((m) => m.machine)).toEqual([
        'a1',
        'a2',
      ]);
    }
  });

  it('a command the gateway forwards is attributed to the job (the audit record feeds the history)', async () => {
    const { gw, feed, json } = await setup();
    feed('a1', [S('idle'), S('running', { job: 'cut.nc' })]);
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const r = await consoleFetch(`${gw.url}/machines/a1/job?action=stop`, {
      headers: { cookie: otto, 'X-Shopdeck-Command': 'xtool.stop' },
    });
    expect(r.status).toBe(200);
    gw.gw.history.observe(entry('a1', 'Laser one'), S('running', { job: 'cut.nc' }), S('idle'));
    const jobs = await json<{ jobs: unknown[] }>(otto, '/api/history/jobs');
    expect(jobs.jobs).toMatchObject([{ name: 'cut.nc', outcome: 'cancelled', stoppedBy: 'otto' }]);
  });
});

describe('/api/history: answers', () => {
  it('CSV cells that a spreadsheet would run are defused', async () => {
    const { gw, feed, get } = await setup();
    feed('a1', [
      S('running', { job: '=HYPERLINK("http://evil.example","click")' }),
      S('alarm', { alarm: '+SUM(A1:A9)', job: '=HYPERLINK("http://evil.example","click")' }),
    ]);
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const jobs = await get(sam, '/api/history/jobs.csv');
    expect(jobs.type).toMatch(/^text\/csv/);
    // (fetch's text() drops the byte order mark the file starts with)
    expect(jobs.text.replace(/^\uFEFF/, '')).toMatch(
      /^id,machine,machine_name,family,job,started,ended,outcome,/,
    );
    expect(jobs.text).toContain(`"'=HYPERLINK(""http://evil.example"",""click"")"`);
    expect(jobs.text).toContain(`"'+SUM(A1:A9)"`);
    const stops = await get(sam, '/api/history/stops.csv');
    expect(stops.text).toContain(`"'+SUM(A1:A9)",1,`);
    const states = await get(sam, '/api/history/states.csv');
    for (const t of [jobs.text, stops.text, states.text])
      for (const cell of t.split(/\r\n/).flatMap((line) => line.split(',')))
        expect(cell.replace(/^\uFEFF/, '')).not.toMatch(/^[=+@\t\r]|^-[^0-9]/);
  });

  it('refuses what it cannot answer', async () => {
    const { gw, get } = await setup();
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    expect((await get(sam, '/api/history/states?from=2000&to=1000')).status).toBe(400);
    expect((await get(sam, '/api/history/states?from=yesterday')).status).toBe(400);
    expect((await get(sam, `/api/history/utilisation?from=0&to=${500 * 86_400_000}`)).status).toBe(400);
    expect((await get(sam, '/api/history/jobs?outcome=exploded')).status).toBe(400);
    expect((await get(sam, '/api/history/jobs?limit=0')).status).toBe(400);
    expect((await get(sam, '/api/history/shift-report?shift=Weekend')).status).toBe(404);
    expect((await get(sam, '/api/history/shift-report?shift=Early&date=2026-02-30')).status).toBe(400);
    expect((await get(sam, '/api/history/nothing')).status).toBe(404);
    const post = await consoleFetch(`${gw.url}/api/history/jobs`, {
      method: 'POST',
      headers: { cookie: sam },
    });
    expect(post.status).toBe(405);
  });

  it('shifts and retention are a supervisor’s settings; the info shows them and the size', async () => {
    const { gw, dir, get, json } = await setup();
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const put = (cookie: string, body: unknown) =>
      consoleFetch(`${gw.url}/api/settings`, {
        method: 'PUT',
        headers: { cookie, 'Content-Type': 'application/json' },
        body: JSON.stringify(body),
      });
    const shifts = [
      { name: 'Day', start: '07:00', end: '19:00' },
      { name: 'Night', start: '19:00', end: '07:00' },
    ];
    expect((await put(otto, { shifts })).status).toBe(403);
    expect((await put(sam, { shifts: [{ name: 'Bad', start: '25:00', end: '07:00' }] })).status).toBe(400);
    expect(
      (await put(sam, { shifts: [...shifts, { name: 'day', start: '01:00', end: '02:00' }] })).status,
    ).toBe(400);
    expect((await put(sam, { retention: { jobsDays: 0, statesDays: 90 } })).status).toBe(400);
    expect((await put(sam, {})).status).toBe(400);
    const ok = await put(sam, { shifts, retention: { jobsDays: 30, statesDays: 7 } });
    expect(ok.status).toBe(200);
    expect(await ok.json()).toMatchObject({ shifts, retention: { jobsDays: 30, statesDays: 7 } });
    const info = await json<Record<string, unknown>>(otto, '/api/history/info');
    expect(info).toMatchObject({ shifts, retention: { jobsDays: 30, statesDays: 7 }, schemaVersion: 4 });
    expect(info['sizeBytes']).toEqual(expect.any(Number));
    expect((await get(sam, '/api/history/shift-report?shift=Early')).status).toBe(404);
    expect((await get(sam, '/api/history/shift-report?shift=Day')).status).toBe(200);
    const settings = await json<{ historyBytes: number }>(sam, '/api/settings');
    expect(settings.historyBytes).toBeGreaterThan(0);
    // Kept across a restart: settings.json.
    expect(JSON.parse(readFileSync(path.join(dir, 'settings.json'), 'utf8'))).toMatchObject({ shifts });
    await gw.gw.audit.flush();
    const audit = JSON.stringify(gw.gw.audit.all());
    expect(audit).toMatch(
      /"type":"settings".*shifts: Day 07:00–19:00, Night 19:00–07:00; history kept: jobs 30 days/,
    );
  });

  it('a history file that cannot be opened: 503 for the history, the console still runs', async () => {
    const { gw, get } = await setup({ brokenFile: true });
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const r = await get(sam, '/api/history/jobs');
    expect(r.status).toBe(503);
    expect(r.text).toMatch(/not available/);
    expect((await get(sam, '/api/machines')).status).toBe(200);
    // The watch's summaries are ignored without a store, not thrown.
    gw.gw.history.observe(entry('a1', 'Laser one'), S('idle'), S('running'));
  });
});

describe('/api/history: recorded by the watch, no page open', () => {
  it('a job a simulated laser runs with nobody watching is in the jobs list', async () => {
    const { xtoolFamily } = await import('../../src/controllers/xtool/family');
    const sharing = xtoolFamily.gateway?.sharing;
    const watch = sharing?.watch;
    if (!sharing || !watch) throw new Error('the xTool family declares no watch');
    const sim: { demo: (() => void) | null } = { demo: null };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: { file: null, machines: [entry('x1', 'Laser')] },
      families: {
        xtool: {
          ...xtoolFamily,
          gateway: { ...xtoolFamily.gateway, sharing: { ...sharing, watch: { ...watch, everyMs: 150 } } },
          createSimulator: (o) => {
            const made = xtoolFamily.createSimulator(o);
            sim.demo = () =>
              made
                .controls?.()
                .find((c) => c.id === 'demo')
                ?.run();
            return made;
          },
        },
      },
      dataDir: t.dir,
      env: {},
      watch: true,
    });
    cleanups.push(gw.close);
    const list = async () =>
      (await (await consoleFetch(`${gw.url}/api/history/jobs`)).json()) as {
        jobs: Array<{ machine: string; outcome: string | null; runningS: number }>;
      };
    const until = async (what: string, ok: () => Promise<boolean>): Promise<void> => {
      const end = Date.now() + 8000;
      while (!(await ok())) {
        if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
        await new Promise((r) => setTimeout(r, 50));
      }
    };
    await until('the simulator', () => Promise.resolve(sim.demo !== null));
    sim.demo?.();
    await until('the job in the history', async () => (await list()).jobs.length > 0);
    const [job] = (await list()).jobs;
    expect(job).toMatchObject({ machine: 'x1', outcome: null });
    const states = (await (await consoleFetch(`${gw.url}/api/history/states?machine=x1`)).json()) as {
      machines: Array<{ intervals: Array<{ state: string; open: boolean }> }>;
    };
    expect(states.machines[0]?.intervals.at(-1)).toMatchObject({ state: 'running', open: true });
  });
});
