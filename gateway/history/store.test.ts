import { spawn } from 'node:child_process';
import { statSync } from 'node:fs';
import path from 'node:path';
import Database from 'better-sqlite3';
import { afterEach, describe, expect, it } from 'vitest';
import type { WatchSummary } from '../../src/fleet/contract';
import { createLogger, type Logger } from '../log';
import { tempDir } from '../test-util';
import { MIGRATIONS, NewerSchemaError, openHistoryDb, schemaVersion } from './db';
import { families } from '../../src/controllers/families';
import { HistoryStore, jobCommandsOf, type HistoryMachine } from './store';
import { S } from './summary.test-util';

/** The history store against a real SQLite file in a temporary folder, on an injected clock. */

const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0).reverse()) c();
});

function setup(start = Date.UTC(2026, 2, 10, 12)) {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const lines: string[] = [];
  const log: Logger = createLogger({ write: (l) => lines.push(l) });
  const clock = { now: start };
  const file = path.join(t.dir, 'history.sqlite');
  const open = (o: { retention?: { jobsDays: number; statesDays: number } } = {}): HistoryStore => {
    const s = new HistoryStore({
      file,
      log,
      now: () => clock.now,
      jobCommands: jobCommandsOf(families),
      ...(o.retention ? { retention: () => o.retention ?? { jobsDays: 365, statesDays: 90 } } : {}),
    });
    cleanups.push(() => {
      if (s.db.open) s.db.close();
    });
    return s;
  };
  return { dir: t.dir, file, clock, lines, log, open };
}

const M: HistoryMachine = { id: 'm1', name: 'Laser', kind: 'xtool' };
/** Feeds summaries at times (ms after the start): as the watch does, each with the one before. */
function feed(
  store: HistoryStore,
  clock: { now: number },
  start: number,
  steps: Array<[number, WatchSummary]>,
  m = M,
) {
  let prev = S('unknown');
  for (const [at, next] of steps) {
    clock.now = start + at;
    store.observe(m, prev, next);
    prev = next;
  }
}

const tables = (db: Database.Database): string[] =>
  db.prepare("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name").pluck().all() as string[];

describe('job commands', () => {
  it("come from each family's jobs declaration: the table the history used before, exactly", () => {
    expect(jobCommandsOf(families)).toEqual({
      'duet.start': 'start',
      'xtool.run-file': 'start',
      'prunt.runFile': 'start',
      'g2core.run-job': 'start',
      'duet.pause': 'pause',
      'xtool.pause': 'pause',
      'prunt.pause': 'pause',
      'g2core.feedhold': 'pause',
      'duet.resume': 'resume',
      'xtool.resume': 'resume',
      'prunt.resume': 'resume',
      'g2core.resume': 'resume',
      'duet.cancel': 'stop',
      'duet.estop': 'stop',
      'xtool.stop': 'stop',
      'prunt.cancel': 'stop',
      'g2core.kill': 'stop',
    });
  });
});

describe('history database: migrations', () => {
  it('creates every table from an empty file, WAL and synchronous NORMAL', () => {
    const { open } = setup();
    const s = open();
    expect(schemaVersion(s.db)).toBe(MIGRATIONS.length);
    expect(s.applied).toEqual(MIGRATIONS.map((m) => m.name));
    expect(tables(s.db)).toEqual([
      'audit',
      'audit_imports',
      'jobs',
      'last_seen',
      'sessions',
      'states',
      'touchcut_days',
    ]);
    expect(s.db.pragma('journal_mode', { simple: true })).toBe('wal');
    expect(s.db.pragma('synchronous', { simple: true })).toBe(1); // NORMAL
    expect(statSync(s.file).mode & 0o777).toBe(0o600);
    s.close();
    // Opened again: nothing to apply.
    expect(open().applied).toEqual([]);
  });

  it('migrates a file of the previous version and keeps what it held', () => {
    const { file, open, clock } = setup();
    const v1 = openHistoryDb(file, MIGRATIONS.slice(0, 1)).db;
    expect(schemaVersion(v1)).toBe(1);
    expect(tables(v1)).toEqual(['jobs', 'last_seen', 'states']);
    v1.prepare(
      "INSERT INTO jobs (machine, family, name, started_at, ended_at, outcome, running_ms, counted_to) VALUES ('m1', 'xtool', 'old.nc', 1000, 61000, 'finished', 60000, 61000)",
    ).run();
    v1.close();
    const s = open();
    expect(s.applied).toEqual(MIGRATIONS.slice(1).map((m) => m.name));
    expect(schemaVersion(s.db)).toBe(MIGRATIONS.length);
    expect(s.jobs({ machines: null }).jobs).toMatchObject([
      { name: 'old.nc', outcome: 'finished', runningMs: 60000 },
    ]);
    s.putTouchcutDay('t1', '2026-03-09', { machine: [] }, clock.now);
    expect(s.touchcutDays({ machines: null })).toHaveLength(1);
  });

  it('a migration that fails is rolled back whole: the file stays at the version before', () => {
    const { file } = setup();
    const broken = [
      ...MIGRATIONS.slice(0, 1),
      { name: 'broken', sql: 'CREATE TABLE half (x INTEGER); INSERT INTO no_such_table VALUES (1);' },
    ];
    expect(() => openHistoryDb(file, broken)).toThrow(/no_such_table/);
    const db = new Database(file);
    expect(schemaVersion(db)).toBe(1);
    expect(tables(db)).not.toContain('half');
    db.close();
  });

  it('refuses a file from a newer Shopdeck and leaves it alone', () => {
    const { file, open } = setup();
    const db = new Database(file);
    db.pragma('user_version = 99');
    db.close();
    expect(() => open()).toThrow(NewerSchemaError);
    const again = new Database(file);
    expect(schemaVersion(again)).toBe(99);
    expect(tables(again)).toEqual([]);
    again.close();
  });
});

describe('history database: a crash between writes', () => {
  it('a process killed inside a transaction leaves the file as of the last commit', async () => {
    const { file, open } = setup();
    open().close();
    // A second process writes one job, commits, then is killed in the middle of a transaction.
    const script = `
      const Database = require('better-sqlite3');
      const db = new Database(process.argv[1]);
      db.pragma('journal_mode = WAL');
      db.pragma('synchronous = NORMAL');
      const ins = db.prepare("INSERT INTO jobs (machine, family, name, started_at, counted_to) VALUES ('m1', 'xtool', ?, 1, 1)");
      ins.run('committed');
      db.exec('BEGIN IMMEDIATE');
      for (let i = 0; i < 5000; i++) ins.run('half-written ' + i);
      process.stdout.write('inside\\n');
      setInterval(() => {}, 1000);
    `;
    const child = spawn(process.execPath, ['-e', script, file], {
      cwd: process.cwd(),
      stdio: ['ignore', 'pipe', 'pipe'],
    });
    let err = '';
    child.stderr.on('data', (d: Buffer) => (err += d.toString()));
    await new Promise<void>((resolve, reject) => {
      child.stdout.on('data', (d: Buffer) => {
        if (d.toString().includes('inside')) resolve();
      });
      child.on('exit', (code) =>
        reject(new Error(`the writer exited (${code}) before its transaction: ${err}`)),
      );
    });
    const exited = new Promise((r) => child.on('exit', r));
    child.kill('SIGKILL');
    await exited;
    const s = open();
    expect(s.db.pragma('integrity_check', { simple: true })).toBe('ok');
    const names = s.db.prepare('SELECT name FROM jobs').pluck().all();
    expect(names).toEqual(['committed']);
  });

  it('an error inside a recording transaction rolls all of it back; the next change records', () => {
    const { open, clock } = setup();
    const s = open();
    // Any job insert fails: the state interval written before it in the same transaction goes too.
    s.db.exec("CREATE TRIGGER boom BEFORE INSERT ON jobs BEGIN SELECT RAISE(ABORT, 'disk says no'); END");
    const t0 = clock.now;
    s.observe(M, S('unknown'), S('running', { job: 'a.nc' }));
    expect(s.db.prepare('SELECT COUNT(*) FROM states').pluck().get()).toBe(0);
    expect(s.db.prepare('SELECT COUNT(*) FROM last_seen').pluck().get()).toBe(0);
    s.db.exec('DROP TRIGGER boom');
    clock.now = t0 + 1000;
    s.observe(M, S('unknown'), S('running', { job: 'a.nc' }));
    clock.now = t0 + 3000;
    expect(s.states({ machines: null, from: t0, to: t0 + 5000 }).intervals).toMatchObject([
      { state: 'running', from: t0 + 1000 },
    ]);
    expect(s.jobs({ machines: null }).jobs).toMatchObject([
      { name: 'a.nc', startedAt: t0 + 1000, outcome: null },
    ]);
  });
});

describe('history: jobs and their outcomes', () => {
  it('finished, cancelled, failed and unknown by the state sequence; who from the commands', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    const min = 60_000;
    clock.now = t0 - 10_000;
    s.command('m1', 'xtool.run-file', 'otto');
    feed(s, clock, t0, [
      [0, S('idle')],
      // 1: runs 10 min, paused 2 min by sam, resumed by otto, runs 3 more, ends: finished
      [1 * min, S('running', { job: 'a.nc', progress: 0.1 })],
      [11 * min, S('paused', { job: 'a.nc', progress: 0.6 })],
      [13 * min, S('running', { job: 'a.nc', progress: 0.6 })],
      [16 * min, S('idle', { job: 'a.nc', progress: 0.99 })],
      // 2: runs 5 min and ends with no stop command: finished
      [20 * min, S('running', { job: 'b.nc' })],
      [25 * min, S('idle')],
      // 3: an alarm ends it: failed
      [30 * min, S('running', { job: 'c.nc' })],
      [31 * min, S('alarm', { alarm: 'Flame detected', job: 'c.nc' })],
      [32 * min, S('idle')],
      // 4: the console loses sight of it, sees it idle again: unknown
      [40 * min, S('running', { job: 'd.nc' })],
      [41 * min, S('offline', { job: 'd.nc' })],
      [45 * min, S('idle')],
    ]);
    const j = s.jobs({ machines: null }).jobs;
    expect(j.map((x) => [x.name, x.outcome])).toEqual([
      ['d.nc', 'unknown'],
      ['c.nc', 'failed'],
      ['b.nc', 'finished'],
      ['a.nc', 'finished'],
    ]);
    const a = j.find((x) => x.name === 'a.nc');
    expect(a).toMatchObject({ runningMs: 13 * min, pausedMs: 2 * min, progress: 0.99, startedBy: 'otto' });
    expect(j.find((x) => x.name === 'c.nc')).toMatchObject({ endAlarm: 'Flame detected', runningMs: min });
    expect(j.find((x) => x.name === 'd.nc')).toMatchObject({ runningMs: min, pausedMs: 0 });
  });

  it('a stop command makes it cancelled, also when the watch saw the stop first', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    feed(s, clock, t0, [
      [0, S('idle')],
      [1000, S('running', { job: 'a.nc' })],
    ]);
    clock.now = t0 + 2000;
    s.command('m1', 'xtool.pause', 'sam');
    feed(s, clock, t0, [[3000, S('paused', { job: 'a.nc' })]]);
    clock.now = t0 + 4000;
    s.command('m1', 'xtool.resume', 'otto (on vera\u2019s tablet)');
    s.command('m1', 'xtool.stop', 'sam');
    feed(s, clock, t0, [[5000, S('idle')]]);
    // The second job: the watch sees idle before the stop command's answer is recorded.
    feed(s, clock, t0, [
      [10_000, S('running', { job: 'b.nc' })],
      [20_000, S('idle')],
    ]);
    clock.now = t0 + 21_000;
    s.command('m1', 'xtool.stop', 'otto');
    // Not a job command: ignored.
    s.command('m1', 'xtool.gcode', 'otto');
    const [b, a] = s.jobs({ machines: null }).jobs;
    expect(a).toMatchObject({
      name: 'a.nc',
      outcome: 'cancelled',
      pausedBy: 'sam',
      resumedBy: 'otto (on vera\u2019s tablet)',
      stoppedBy: 'sam',
    });
    expect(b).toMatchObject({ name: 'b.nc', outcome: 'cancelled', stoppedBy: 'otto' });
  });

  it('filters jobs by machine, family, outcome, range and text; the allowed machines first', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    const other: HistoryMachine = { id: 'm2', name: 'Router', kind: 'g2core' };
    feed(s, clock, t0, [
      [0, S('running', { job: 'bracket_50%.nc' })],
      [1000, S('idle')],
    ]);
    feed(
      s,
      clock,
      t0,
      [
        [2000, S('running', { job: 'plate.nc' })],
        [3000, S('alarm', { alarm: 'Limit switch' })],
      ],
      other,
    );
    const names = (q: Partial<Parameters<HistoryStore['jobs']>[0]>) =>
      s.jobs({ machines: null, ...q }).jobs.map((j) => j.name);
    expect(names({})).toEqual(['plate.nc', 'bracket_50%.nc']);
    expect(names({ machines: ['m1'] })).toEqual(['bracket_50%.nc']);
    expect(names({ machines: ['m1'], machine: 'm2' })).toEqual([]);
    expect(names({ family: 'g2core' })).toEqual(['plate.nc']);
    expect(names({ outcome: 'failed' })).toEqual(['plate.nc']);
    expect(names({ q: '50%' })).toEqual(['bracket_50%.nc']);
    expect(names({ q: '_' })).toEqual(['bracket_50%.nc']);
    expect(names({ q: 'limit' })).toEqual(['plate.nc']);
    expect(names({ from: t0 + 1500 })).toEqual(['plate.nc']);
    expect(names({ to: t0 + 1500 })).toEqual(['bracket_50%.nc']);
    expect(s.jobs({ machines: null, limit: 1, offset: 1 })).toMatchObject({
      total: 2,
      jobs: [{ name: 'bracket_50%.nc' }],
    });
  });
});

describe('history: a console restart', () => {
  it('closes a running job as unknown, and the open state, at the last-seen time', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    feed(s, clock, t0, [
      [0, S('idle')],
      [1000, S('running', { job: 'a.nc', progress: 0.25 })],
    ]);
    for (const at of [5000, 10_000, 15_000]) {
      clock.now = t0 + at;
      s.heartbeat();
    }
    // A summary with no change 2 s later: last seen is not written again yet (at most every 5 s).
    clock.now = t0 + 17_000;
    s.observe(M, S('running', { job: 'a.nc' }), S('running', { job: 'a.nc', progress: 0.3 }));
    // The console is killed: no close(), no last heartbeat.
    s.db.close();
    clock.now = t0 + 3_600_000;
    const again = open();
    expect(again.recovered).toEqual({ jobs: 1, states: 1 });
    expect(again.jobs({ machines: null }).jobs).toMatchObject([
      { name: 'a.nc', outcome: 'unknown', endedAt: t0 + 15_000, runningMs: 14_000, progress: 0.25 },
    ]);
    const iv = again.states({ machines: null, from: t0, to: clock.now }).intervals;
    expect(iv).toEqual([
      { machine: 'm1', state: 'idle', alarm: null, from: t0, to: t0 + 1000, open: false },
      { machine: 'm1', state: 'running', alarm: null, from: t0 + 1000, to: t0 + 15_000, open: false },
    ]);
    // The machine still runs: a new job from the moment the console sees it again.
    again.observe(M, S('unknown'), S('running', { job: 'a.nc' }));
    expect(again.jobs({ machines: null, outcome: 'open' }).jobs).toMatchObject([
      { name: 'a.nc', startedAt: clock.now },
    ]);
  });

  it('a clean stop writes the last-seen time on close', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    feed(s, clock, t0, [[0, S('running', { job: 'a.nc' })]]);
    clock.now = t0 + 7000;
    s.close();
    const again = open();
    expect(again.jobs({ machines: null }).jobs).toMatchObject([{ endedAt: t0 + 7000, runningMs: 7000 }]);
  });
});

describe('history: utilisation, stops and retention', () => {
  it('sums each state clipped to the range, open intervals to now, the rest unrecorded', () => {
    const { open, clock } = setup();
    const s = open();
    const t0 = clock.now;
    feed(s, clock, t0, [
      [10_000, S('idle')],
      [20_000, S('running', { job: 'a' })],
      [50_000, S('alarm', { alarm: 'E-stop' })],
      [55_000, S('alarm', { alarm: 'E-stop; Door open' })],
      [60_000, S('idle')],
      [70_000, S('alarm', { alarm: 'E-stop' })],
    ]);
    clock.now = t0 + 80_000;
    const u = s.utilisation({ machines: null, from: t0 + 15_000, to: t0 + 200_000 }).get('m1');
    expect(u).toEqual({
      running: 30_000,
      paused: 0,
      idle: 5000 + 10_000,
      alarm: 5000 + 5000 + 10_000,
      offline: 0,
      unknown: 0,
      unrecorded: 0,
    });
    expect(s.utilisation({ machines: null, from: t0, to: t0 + 30_000 }).get('m1')).toMatchObject({
      idle: 10_000,
      running: 10_000,
      unrecorded: 10_000,
    });
    expect(s.utilisation({ machines: ['other'], from: t0, to: t0 + 30_000 }).size).toBe(0);
    expect(s.stops({ machines: null, from: t0, to: t0 + 100_000 })).toEqual([
      { alarm: 'E-stop', count: 2, ms: 15_000, machines: ['m1'] },
      { alarm: 'E-stop; Door open', count: 1, ms: 5000, machines: ['m1'] },
    ]);
  });

  it('prunes jobs, state changes and TouchCut days past the retention; open ones stay', () => {
    const day = 86_400_000;
    const { open, clock } = setup();
    const retention = { jobsDays: 365, statesDays: 90 };
    const s = open({ retention });
    const t0 = clock.now;
    feed(s, clock, t0, [
      [0, S('running', { job: 'very old' })],
      [1000, S('idle')],
      [100 * day, S('running', { job: 'old' })],
      [100 * day + 1000, S('idle')],
      [400 * day, S('running', { job: 'recent' })],
      [400 * day + 1000, S('idle')],
      [440 * day, S('running', { job: 'open' })],
    ]);
    s.putTouchcutDay('t1', '2025-01-01', {}, clock.now);
    s.putTouchcutDay('t1', '2027-04-01', {}, clock.now);
    clock.now = t0 + 450 * day;
    const pruned = s.prune();
    // Jobs: ended before day 85; states: ended before day 360.
    expect(pruned).toEqual({ jobs: 1, states: 3, touchcutDays: 1 });
    expect(s.jobs({ machines: null }).jobs.map((j) => j.name)).toEqual(['open', 'recent', 'old']);
    const left = s.db.prepare('SELECT started_at FROM states ORDER BY started_at').pluck().all();
    expect(left).toEqual([t0 + 100 * day + 1000, t0 + 400 * day, t0 + 400 * day + 1000, t0 + 440 * day]);
    expect(s.touchcutDays({ machines: null }).map((d) => d.day)).toEqual(['2027-04-01']);
    expect(s.info()).toMatchObject({ counts: { jobs: 3, states: 4, touchcutDays: 1 }, retention });
    // Shorter retention, pruned again: the rest of what ended before the new limits goes.
    retention.statesDays = 30;
    expect(s.prune()).toMatchObject({ states: 2 });
    expect(s.info().sizeBytes).toBeGreaterThan(0);
  });

  it('a big prune (a shorter retention) goes a batch at a time, letting the thread work in between', async () => {
    const day = 86_400_000;
    const { open, clock } = setup();
    const s = open({ retention: { jobsDays: 365, statesDays: 1 } });
    const ins = s.db.prepare(
      "INSERT INTO states (machine, state, alarm, started_at, ended_at) VALUES ('m1', 'idle', NULL, ?, ?)",
    );
    const old = clock.now - 10 * day;
    s.db.transaction(() => {
      for (let k = 0; k < 22_000; k++) ins.run(old + k, old + k + 1);
    })();
    // Turns the event loop gets while it prunes (none if it held the thread throughout).
    let turns = 0;
    let going = true;
    const spin = (): void => {
      if (!going) return;
      turns++;
      setImmediate(spin);
    };
    setImmediate(spin);
    const pruned = await s.pruneGently();
    going = false;
    expect(pruned).toEqual({ jobs: 0, states: 22_000, touchcutDays: 0 });
    expect(turns).toBeGreaterThanOrEqual(4); // 22,000 rows: 5 batches of at most 5000
    expect(s.info().counts.states).toBe(0);
  });
});
