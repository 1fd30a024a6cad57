import { existsSync, mkdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import Database from 'better-sqlite3';
import { afterEach, describe, expect, it } from 'vitest';
import { duetAccess } from '../src/controllers/duet/access';
import { g2coreAccess, g2coreAccessNeedsBody } from '../src/controllers/g2core/access';
import { pruntAccess } from '../src/controllers/prunt/access';
import { touchcutAccess } from '../src/controllers/touchcut/access';
import { xtoolAccess } from '../src/controllers/xtool/access';
import { xtoolFamily } from '../src/controllers/xtool/family';
import type { AccessPolicy } from '../src/fleet/access';
import { families } from '../src/controllers/families';
import { jobCommandsOf } from './history/store';
import type { WatchSummary } from '../src/fleet/contract';
import { AUDIT_DB_FILE, AuditLog, type AuditEntry, type AuditQuery } from './audit';
import { createLogger, type Logger } from './log';
import {
  consoleFetch,
  gatewayFor,
  login,
  startGateway,
  stubEntry,
  stubFor,
  tempDir,
  testFamily,
  user,
  type Cleanups,
} from './test-util';

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function dir(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return t.dir;
}

function captured(): { log: Logger; lines: string[] } {
  const lines: string[] = [];
  return { log: createLogger({ json: true, write: (l) => lines.push(l) }), lines };
}

function opened(d: string, opts: ConstructorParameters<typeof AuditLog>[1] = {}): AuditLog {
  const a = new AuditLog(d, { role: 'server', log: captured().log, ...opts });
  cleanups.push(() => a.close());
  return a;
}

const DAY = 86_400_000;
const T0 = Date.UTC(2026, 2, 1);

/** Entry n: machine a or b, user u<n mod 3>, result ok or error, time n seconds after midnight. */
function entry(n: number): Omit<AuditEntry, 'time'> & { time: string } {
  return {
    time: new Date(T0 + n * 1000).toISOString(),
    type: 'command',
    result: n % 4 === 0 ? 'error' : 'ok',
    user: `u${n % 3}`,
    source: 'gateway',
    machine: n % 2 ? 'a' : 'b',
    detail: `#${n}`,
  };
}

describe('the audit table (history.sqlite)', () => {
  it('answers pages newest first with the total of every filter, as the file log did', async () => {
    const a = opened(dir());
    const all = Array.from({ length: 150 }, (_, n) => entry(n));
    for (const e of all) a.append(e);
    a.append({ ...entry(150), machine: undefined, type: 'login', user: 'sam', onBehalfOf: 'u1' });
    const everything = [
      ...all,
      { ...entry(150), machine: undefined, type: 'login' as const, user: 'sam', onBehalfOf: 'u1' },
    ];
    const queries: AuditQuery[] = [
      {},
      { machine: 'a' },
      { user: 'u1' },
      { result: 'error', machine: 'b' },
      { from: T0 + 50_000, to: T0 + 100_000 },
      { machines: ['a'] },
      { offset: 140, limit: 50 },
    ];
    for (const q of queries) {
      const want = everything
        .filter(
          (e) =>
            (!q.machine || e.machine === q.machine) &&
            (!q.machines || e.machine === undefined || q.machines.includes(e.machine)) &&
            (!q.user || e.user === q.user || e.onBehalfOf === q.user) &&
            (!q.result || e.result === q.result) &&
            (q.from === undefined || Date.parse(e.time) >= q.from) &&
            (q.to === undefined || Date.parse(e.time) <= q.to),
        )
        .reverse();
      const got = await a.query(q);
      expect(got.total).toBe(want.length);
      const offset = q.offset ?? 0;
      expect(got.entries.map((e) => e.detail)).toEqual(
        want.slice(offset, offset + (q.limit ?? 50)).map((e) => e.detail),
      );
      expect((await a.filtered(q)).map((e) => e.detail)).toEqual(want.map((e) => e.detail));
    }
    expect(a.all()).toHaveLength(151);
  });

  it('keeps commands, logins and settings 400 days; refusals 30 days and at most refusalMax', () => {
    let now = T0;
    const a = opened(dir(), { now: () => now, retention: { refusalMax: 20 } });
    a.append({
      time: new Date(now).toISOString(),
      type: 'command',
      result: 'ok',
      user: 'sam',
      source: 'gateway',
      machine: 'p1',
    });
    a.append({
      time: new Date(now).toISOString(),
      type: 'login',
      result: 'ok',
      user: 'sam',
      source: 'gateway',
    });
    a.append({
      time: new Date(now).toISOString(),
      type: 'settings',
      result: 'ok',
      user: 'sam',
      source: 'gateway',
    });
    for (let i = 0; i < 100; i++)
      a.append({
        time: new Date(now + i).toISOString(),
        type: 'refused',
        result: 'refused',
        user: 'vic',
        source: 'gateway',
        detail: `r${i}`,
      });
    const refusals = () => a.all().filter((e) => e.type === 'refused');
    // Bounded in count, the newest kept; the records untouched.
    expect(refusals()).toHaveLength(20);
    expect(refusals().at(-1)?.detail).toBe('r99');
    expect(
      a
        .all()
        .filter((e) => e.type !== 'refused')
        .map((e) => e.type),
    ).toEqual(['command', 'login', 'settings']);
    // 31 days later the refusals are gone, the records stay …
    now = T0 + 31 * DAY;
    a.prune();
    expect(refusals()).toHaveLength(0);
    expect(a.all().map((e) => e.type)).toEqual(['command', 'login', 'settings']);
    now = T0 + 399 * DAY;
    a.prune();
    expect(a.all()).toHaveLength(3);
    // … until 400 days have passed.
    now = T0 + 401 * DAY;
    a.prune();
    expect(a.all()).toHaveLength(0);
  });

  it('imports audit.jsonl and its rotated files once (a torn line skipped), then renames them', () => {
    const d = dir();
    const line = (n: number): string => JSON.stringify(entry(n));
    writeFileSync(path.join(d, 'audit.2.jsonl'), `${line(1)}\n${line(2)}\n`);
    writeFileSync(path.join(d, 'audit.1.jsonl'), `${line(3)}\n`);
    writeFileSync(path.join(d, 'audit.jsonl'), `${line(4)}\n{"time":"2026-03-01T00:00:0`);
    const c = captured();
    const a = opened(d, { log: c.log });
    expect(a.all().map((e) => e.detail)).toEqual(['#1', '#2', '#3', '#4']);
    expect(existsSync(path.join(d, 'audit.jsonl'))).toBe(false);
    expect(existsSync(path.join(d, 'audit.jsonl.imported'))).toBe(true);
    expect(c.lines.join('\n')).toMatch(/imported 4 entries/);
    void a.close();
    // Renaming failed last time (the same file is still there): not imported twice.
    writeFileSync(path.join(d, 'audit.1.jsonl'), `${line(3)}\n`);
    const b = opened(d);
    expect(b.all().map((e) => e.detail)).toEqual(['#1', '#2', '#3', '#4']);
  });

  it('a command is committed as pending before it is sent; a killed gateway’s pending one is closed at the next start', () => {
    const d = dir();
    const a = opened(d);
    const { id, entry: e } = a.begin({
      type: 'command',
      user: 'sam',
      source: 'gateway',
      machine: 'p1',
      path: '/job?action=stop',
    });
    // Another connection (a new process after a SIGKILL) sees it at once.
    const other = new Database(path.join(d, AUDIT_DB_FILE), { readonly: true });
    expect(other.prepare('SELECT result FROM audit WHERE id = ?').get(id)).toEqual({ result: 'pending' });
    other.close();
    a.finish(id, { ...e, result: 'ok', status: 200 });
    expect(a.all()[0]).toMatchObject({ result: 'ok', status: 200 });
    a.begin({ type: 'command', user: 'sam', source: 'gateway', machine: 'p1', path: '/job?action=pause' });
    void a.close(); // as if killed: no outcome written
    const b = opened(d);
    expect(b.all().map((x) => [x.path, x.result])).toEqual([
      ['/job?action=stop', 'ok'],
      ['/job?action=pause', 'error'],
    ]);
    expect(b.all()[1]?.error).toMatch(/stopped before the answer/);
    // A tool (npm run user) opening the same file does not touch a running gateway's pending ones.
    const pending = b.begin({ type: 'command', user: 'sam', source: 'gateway', machine: 'p1' });
    const tool = new AuditLog(d, { log: captured().log });
    tool.append({ type: 'role-change', result: 'ok', user: 'otto', source: 'cli' });
    void tool.close();
    expect(b.all().find((x) => x.time === pending.entry.time && x.type === 'command')?.result).toBe(
      'pending',
    );
    expect(b.all().at(-1)?.type).toBe('role-change');
  });
});

// ---------------------------------------------------------------- attacks, real gateway, real sockets

describe('attacks on the audit log', () => {
  it('(4) a viewer flooding forged commands cannot push a supervisor’s command out; refusals are aggregated', async () => {
    const s = await stubFor(cleanups);
    let clock = Date.now();
    const gw = await gatewayFor(cleanups, [stubEntry('p1', s.url)], {
      users: [user('sam', 'supervisor', 'sam-pass-1'), user('vic', 'viewer', 'vic-pass-1')],
      now: () => clock,
      audit: { retention: { refusalMax: 40 } },
    });
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const vic = await login(gw.url, 'vic', 'vic-pass-1');
    // The supervisor switches the flame alarm off (here: the test family's operator command).
    const ok = await consoleFetch(`${gw.url}/machines/p1/job?action=stop`, { headers: { cookie: sam } });
    expect(ok.status).toBe(200);
    // The viewer floods: 2000 forged commands, 50 at a time, over 10 minutes of the gateway's clock.
    let refused = 0;
    for (let sent = 0; sent < 2000; sent += 50) {
      const answers = await Promise.all(
        Array.from({ length: 50 }, () =>
          consoleFetch(`${gw.url}/machines/p1/job?action=stop`, { headers: { cookie: vic } }).then(
            async (r) => {
              await r.arrayBuffer();
              return r.status;
            },
          ),
        ),
      );
      refused += answers.filter((st) => st === 403).length;
      if ((sent + 50) % 200 === 0) clock += 61_000;
    }
    expect(refused).toBe(2000);
    expect(s.seen).toHaveLength(1); // only the supervisor's command reached the controller
    clock += 61_000;
    gw.gw.close(); // pending summaries written
    const all = gw.gw.audit.all();
    expect(all.filter((e) => e.type === 'command')).toEqual([
      expect.objectContaining({ user: 'sam', commandId: 'test.stop', result: 'ok', status: 200 }),
    ]);
    const vics = all.filter((e) => e.type === 'refused' && e.user === 'vic');
    // Bounded in count, and aggregated: at most 10 written one by one per minute, the rest summed.
    expect(vics.length).toBeLessThanOrEqual(40);
    const summaries = vics.filter((e) =>
      /^\d+ more refused requests by vic \(from .*\) in the last minute \(machines: p1\)$/.test(
        e.detail ?? '',
      ),
    );
    expect(summaries.length).toBeGreaterThan(0);
    const single = vics.filter((e) => !summaries.includes(e));
    const perMinute = new Map<number, number>();
    for (const e of single) {
      const k = Math.floor(Date.parse(e.time) / 61_000);
      perMinute.set(k, (perMinute.get(k) ?? 0) + 1);
    }
    for (const n of perMinute.values()) expect(n).toBeLessThanOrEqual(10);
    // The HTTP API still finds it, with its total.
    const api = await gw.gw.audit.query({ user: 'sam', result: 'ok' });
    expect(api.total).toBeGreaterThanOrEqual(1);
    expect(api.entries.some((e) => e.type === 'command')).toBe(true);
  }, 60_000);

  it('(15) a command’s entry is committed before the request reaches the controller', async () => {
    const s = await stubFor(cleanups);
    const gw = await gatewayFor(cleanups, [stubEntry('p1', s.url)]);
    const file = path.join(gw.gw.audit.dataDir, AUDIT_DB_FILE);
    const atController: unknown[] = [];
    s.respond = (req, res) => {
      // In the controller's own request handler, through another connection (what a new process
      // reads after a SIGKILL now): the entry is there already.
      const db = new Database(file, { readonly: true });
      atController.push(
        db
          .prepare(
            "SELECT type, result, json_extract(entry, '$.path') AS path FROM audit WHERE type = 'command' ORDER BY id DESC",
          )
          .get(),
      );
      db.close();
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end('{}');
    };
    const r = await consoleFetch(`${gw.url}/machines/p1/job?action=pause`);
    expect(r.status).toBe(200);
    expect(atController).toEqual([{ type: 'command', result: 'pending', path: '/job?action=pause' }]);
    expect(gw.gw.audit.all().find((e) => e.type === 'command')).toMatchObject({ result: 'ok', status: 200 });
  });

  it('(15) a command that cannot be audited is not sent: 503, and the server log says why', async () => {
    const s = await stubFor(cleanups);
    const d = dir();
    mkdirSync(path.join(d, AUDIT_DB_FILE)); // the database cannot be opened
    const c = captured();
    const broken = await startGateway({
      families: { prunt: testFamily('prunt') },
      env: {},
      machines: { file: null, machines: [stubEntry('p1', s.url)] },
      dataDir: d,
      log: c.log,
    });
    cleanups.push(broken.close);
    const r = await consoleFetch(`${broken.url}/machines/p1/job?action=stop`);
    expect(r.status).toBe(503);
    expect(await r.json()).toMatchObject({
      gateway: true,
      error: expect.stringMatching(/audit log cannot be written/),
    });
    expect(s.seen).toHaveLength(0);
    expect(c.lines.join('\n')).toMatch(/a command was refused: its audit entry cannot be written/);
    // Reads still work.
    expect((await consoleFetch(`${broken.url}/machines/p1/status`)).status).toBe(200);
  });

  it('(9) a pause with a forged X-Shopdeck-Command is audited as the pause; the history records no cancel', async () => {
    const s = await stubFor(cleanups);
    const m = stubEntry('x1', s.url, { kind: 'xtool' });
    const gw = await gatewayFor(cleanups, [m], { families: { xtool: xtoolFamily } });
    const at = (state: WatchSummary['state']): WatchSummary => ({ state, alarm: null, job: 'part.nc' });
    // A job ran and finished by itself.
    gw.gw.history.observe(m, at('idle'), at('running'));
    gw.gw.history.observe(m, at('running'), at('idle'));
    const outcome = () => gw.gw.history.store?.jobs({ machines: null }).jobs[0]?.outcome;
    expect(outcome()).toBe('finished');
    // A pause, with the header of a stop.
    const r = await consoleFetch(`${gw.url}/machines/x1/cnc/data?action=pause`, {
      headers: { 'X-Shopdeck-Command': 'xtool.stop' },
    });
    expect(r.status).toBe(200);
    expect(gw.gw.audit.all().find((e) => e.type === 'command')).toMatchObject({
      commandId: 'xtool.pause',
      clientCommand: 'xtool.stop',
      path: '/cnc/data?action=pause',
    });
    expect(outcome()).toBe('finished');
    // A real stop (whatever its header says) right after the end is believed: cancelled.
    await consoleFetch(`${gw.url}/machines/x1/cnc/data?action=stop`, {
      headers: { 'X-Shopdeck-Command': 'xtool.pause' },
    });
    expect(outcome()).toBe('cancelled');
  });
});

describe('the command a request is, as the families classify it (the audit’s commandId)', () => {
  const ask = (policy: AccessPolicy, method: string, target: string, body?: string) => {
    const [p, q] = target.split('?');
    return policy({ method, path: p ?? '/', query: new URLSearchParams(q ?? ''), body }).id;
  };

  it('names every job command from the request itself, and only job commands the history knows', () => {
    const cases: Array<[string | undefined, string | undefined]> = [
      [ask(xtoolAccess, 'GET', '/cnc/data?action=pause'), 'xtool.pause'],
      [ask(xtoolAccess, 'GET', '/cnc/data?action=stop'), 'xtool.stop'],
      [ask(xtoolAccess, 'GET', '/cnc/data?action=resume'), 'xtool.resume'],
      [ask(xtoolAccess, 'GET', '/read?file=/a.gcode'), 'xtool.run-file'],
      [ask(xtoolAccess, 'GET', '/cnc/data?action=constructor'), undefined],
      [ask(pruntAccess, 'POST', '/pause/pause'), 'prunt.pause'],
      [ask(pruntAccess, 'POST', '/cancel'), 'prunt.cancel'],
      [ask(pruntAccess, 'POST', '/run-file'), 'prunt.runFile'],
      [ask(duetAccess, 'POST', '/machine/code', 'M25'), 'duet.pause'],
      [ask(duetAccess, 'POST', '/machine/code', 'M24'), 'duet.resume'],
      [ask(duetAccess, 'POST', '/machine/code', 'M0'), 'duet.cancel'],
      [ask(duetAccess, 'POST', '/machine/code', 'M112\nM999'), 'duet.estop'],
      [ask(duetAccess, 'POST', '/machine/code', 'M32 "0:/gcodes/a.gcode"'), 'duet.start'],
      // A pause that also cancels is a cancel.
      [ask(duetAccess, 'POST', '/machine/code', 'M25\nM0'), 'duet.cancel'],
      [ask(duetAccess, 'GET', '/rr_gcode?gcode=M25'), 'duet.pause'],
      [ask(g2coreAccess, 'PUT', '/operation/7', '{"opstate":"pause"}'), 'g2core.feedhold'],
      [ask(g2coreAccess, 'PUT', '/operation/7', '{"opstate":"run"}'), 'g2core.resume'],
      [ask(g2coreAccess, 'PUT', '/operation/7', '{"opstate":"kill"}'), 'g2core.kill'],
      [ask(g2coreAccess, 'PUT', '/job/3', '{"state":"run"}'), 'g2core.run-job'],
      [ask(g2coreAccess, 'PUT', '/job/3', '{"state":"kill"}'), 'g2core.kill'],
      [ask(g2coreAccess, 'PUT', '/job/3', '{"state":"kill","state":"run"}'), undefined],
      [ask(g2coreAccess, 'PUT', '/job/3', '{"position":2}'), undefined],
    ];
    for (const [got, want] of cases) expect(got).toBe(want);
    for (const [got] of cases)
      if (got && got !== 'duet.simulate') expect(jobCommandsOf(families)[got]).toBeDefined();
    // The same class of mistake (a name looked up among an object's inherited keys) is closed:
    // an action or resource called `constructor` is unknown, so supervisor only.
    const role = (policy: AccessPolicy, target: string) =>
      policy({
        method: 'GET',
        path: target.split('?')[0] ?? '/',
        query: new URLSearchParams(target.split('?')[1] ?? ''),
      }).role;
    expect(role(xtoolAccess, '/cnc/data?action=constructor')).toBe('supervisor');
    expect(role(touchcutAccess, '/rest/v1/constructor')).toBe('supervisor');
    expect(role(touchcutAccess, '/rest/v1/__proto__')).toBe('supervisor');
    expect(role(touchcutAccess, '/rest/v1/status')).toBe('viewer');
    // g2core's controls are read to be classified.
    expect(g2coreAccessNeedsBody('PUT', '/job/3')).toBe(true);
    expect(g2coreAccessNeedsBody('PUT', '/operation/7')).toBe(true);
  });
});
