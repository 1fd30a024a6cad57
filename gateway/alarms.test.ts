import { spawn } from 'node:child_process';
import { appendFileSync, existsSync, readdirSync, readFileSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { afterEach, describe, expect, it } from 'vitest';
import type { WatchSummary } from '../src/fleet/contract';
import { AlarmCentre, OFFLINE_KEY, type AlarmEvent, type AlarmRecord } from './alarms';
import { createLogger } from './log';
import { tempDir } from './test-util';

const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0)) c();
});

const laser = { id: 'laser-1', name: 'Laser 1', kind: 'xtool' };
const cnc = { id: 'cnc-1', name: 'CNC 1', kind: 'g2core' };
const FLAME = { key: 'xtool-flame', severity: 'critical' as const, text: 'FLAME DETECTED' };
const TILT = { key: 'xtool-tilt', severity: 'warning' as const, text: 'Tilt sensor tripped' };

function sum(
  state: WatchSummary['state'],
  alarms?: WatchSummary['alarms'],
  job: string | null = null,
): WatchSummary {
  return { state, alarm: alarms?.map((a) => a.text).join('; ') || null, job, ...(alarms ? { alarms } : {}) };
}

function setup(dataDir: string | null = null) {
  const clock = { t: Date.parse('2026-11-25T03:00:00Z') };
  const lines: string[] = [];
  const events: Array<[AlarmEvent, string]> = [];
  const log = createLogger({ write: (l) => lines.push(l) });
  const centre = new AlarmCentre({
    dataDir,
    log,
    now: () => clock.t,
    onChange: (e, r) => events.push([e, r.id]),
  });
  return { centre, clock, lines, events };
}

describe('the alarm centre', () => {
  it('opens a record when a machine raises an alarm, clears it when the controller does, keeps it', () => {
    const { centre, clock, events } = setup();
    centre.observe(laser, sum('unknown'), sum('running', [], 'a.gc'));
    expect(centre.query({ machines: null })).toEqual([]);
    clock.t += 1000;
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    const [r] = centre.query({ machines: null });
    expect(r).toMatchObject({
      machine: 'laser-1',
      machineName: 'Laser 1',
      family: 'xtool',
      key: 'xtool-flame',
      severity: 'critical',
      text: 'FLAME DETECTED',
      clearedAt: null,
      ackBy: null,
    });
    // The same alarm again is the same record.
    centre.observe(laser, sum('alarm', [FLAME]), sum('alarm', [FLAME]));
    expect(centre.query({ machines: null })).toHaveLength(1);
    clock.t += 5000;
    centre.observe(laser, sum('alarm', [FLAME]), sum('idle', []));
    const [cleared] = centre.query({ machines: null });
    expect(cleared?.clearedAt).toBe(clock.t);
    expect(centre.query({ machines: null, state: 'active' })).toEqual([]);
    // Cleared by the controller is not acknowledged by a person.
    expect(centre.query({ machines: null, state: 'unacknowledged' })).toHaveLength(1);
    expect(events.map((e) => e[0])).toEqual(['alarm.raised', 'alarm.cleared']);
  });

  it('a summary without alarms (the family did not say) changes nothing', () => {
    const { centre } = setup();
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    centre.observe(laser, sum('alarm', [FLAME]), sum('alarm'));
    expect(centre.query({ machines: null, state: 'active' })).toHaveLength(1);
  });

  it('acknowledges once, with who and when; a second acknowledgement says it was already done', () => {
    const { centre, clock, events } = setup();
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    const id = centre.query({ machines: null })[0]?.id ?? '';
    clock.t += 30_000;
    const r = centre.acknowledge(id, 'olga');
    expect(r).toMatchObject({ ackBy: 'olga', ackAt: clock.t });
    expect(centre.acknowledge(id, 'sam')).toBe('already');
    expect(centre.get(id)?.ackBy).toBe('olga');
    expect(centre.acknowledge('nope', 'sam')).toBeNull();
    expect(events.filter((e) => e[0] === 'alarm.acknowledged')).toHaveLength(1);
  });

  it('a flame sent again after the last one was acknowledged is a new alarm, even before a poll cleared it', () => {
    const { centre, clock } = setup();
    centre.observe(laser, sum('running', []), { ...sum('alarm', [FLAME]), raised: ['xtool-flame'] });
    const first = centre.query({ machines: null })[0]?.id ?? '';
    centre.acknowledge(first, 'olga');
    clock.t += 3000;
    // The same open record seen again by a poll-like summary: nothing new.
    centre.observe(laser, sum('alarm', [FLAME]), sum('alarm', [FLAME]));
    expect(centre.query({ machines: null })).toHaveLength(1);
    // The laser sends the flame again (an event): a new, unacknowledged record; the old one ends.
    centre.observe(laser, sum('alarm', [FLAME]), { ...sum('alarm', [FLAME]), raised: ['xtool-flame'] });
    const all = centre.query({ machines: null });
    expect(all).toHaveLength(2);
    expect(all[0]).toMatchObject({ key: 'xtool-flame', ackBy: null, clearedAt: null });
    expect(centre.get(first)).toMatchObject({ ackBy: 'olga', clearedAt: clock.t });
  });

  it('nothing is acknowledged in advance: a key without an open record is refused and not kept', () => {
    const { centre, clock, events } = setup();
    expect(centre.acknowledgeKey('laser-1', 'xtool-flame', 'olga')).toBeNull();
    expect(centre.acknowledgeKey('laser-1', 'invented-key', 'olga')).toBeNull();
    clock.t += 2000;
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    const [r] = centre.query({ machines: null });
    expect(r).toMatchObject({ key: 'xtool-flame', ackBy: null, ackAt: null });
    // The open record is acknowledged by its key once it exists.
    expect(centre.acknowledgeKey('laser-1', 'xtool-flame', 'olga')).toMatchObject({ ackBy: 'olga' });
    expect(centre.acknowledgeKey('laser-1', 'xtool-flame', 'sam')).toBe('already');
    // A cleared record is not open: its key acknowledges nothing.
    centre.observe(laser, sum('alarm', [FLAME]), sum('idle', []));
    expect(centre.acknowledgeKey('laser-1', 'xtool-flame', 'olga')).toBeNull();
    expect(events.filter((e) => e[0] === 'alarm.acknowledged')).toHaveLength(1);
  });

  it('a machine that goes offline during a job is an alarm; it clears when the machine answers again', () => {
    const { centre, clock } = setup();
    centre.observe(cnc, sum('idle', []), sum('running', [], 'bracket.nc'));
    clock.t += 10_000;
    centre.observe(cnc, sum('running', [], 'bracket.nc'), sum('offline', undefined, 'bracket.nc'));
    const [r] = centre.query({ machines: null, state: 'active' });
    expect(r).toMatchObject({ key: OFFLINE_KEY, severity: 'warning' });
    expect(r?.text).toMatch(/offline while running a job \(bracket\.nc\)/);
    clock.t += 10_000;
    centre.observe(cnc, sum('offline'), sum('idle', []));
    expect(centre.query({ machines: null, state: 'active' })).toEqual([]);
    // An idle machine switched off for the night is not an alarm.
    centre.observe(cnc, sum('idle', []), sum('offline'));
    expect(centre.query({ machines: null, state: 'active' })).toEqual([]);
  });

  it('an offline machine keeps its alarms as last known', () => {
    const { centre } = setup();
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    centre.observe(laser, sum('alarm', [FLAME]), { ...sum('offline'), alarms: [] });
    expect(centre.query({ machines: null, state: 'active' }).map((r) => r.key)).toEqual(['xtool-flame']);
  });

  it('lists newest and most severe first, filtered by machine, family, severity and the asker’s machines', () => {
    const { centre, clock } = setup();
    centre.observe(laser, sum('running', []), sum('alarm', [TILT]));
    clock.t += 1000;
    centre.observe(
      cnc,
      sum('running', []),
      sum('alarm', [{ key: 'g2core-alarm', severity: 'critical', text: 'ALARM' }]),
    );
    clock.t += 1000;
    centre.observe(laser, sum('alarm', [TILT]), sum('alarm', [TILT, FLAME]));
    const keys = (rs: AlarmRecord[]) => rs.map((r) => r.key);
    expect(keys(centre.query({ machines: null }))).toEqual(['xtool-flame', 'g2core-alarm', 'xtool-tilt']);
    expect(keys(centre.query({ machines: null, machine: 'cnc-1' }))).toEqual(['g2core-alarm']);
    expect(keys(centre.query({ machines: null, family: 'xtool' }))).toEqual(['xtool-flame', 'xtool-tilt']);
    expect(keys(centre.query({ machines: null, severity: 'warning' }))).toEqual(['xtool-tilt']);
    expect(keys(centre.query({ machines: ['cnc-1'] }))).toEqual(['g2core-alarm']);
    expect(keys(centre.query({ machines: [] }))).toEqual([]);
  });

  it('is bounded: cleared records past their time go, then the oldest acknowledged ones', () => {
    const clock = { t: 0 };
    const centre = new AlarmCentre({
      dataDir: null,
      log: createLogger({ write: () => undefined }),
      now: () => clock.t,
      maxRecords: 3,
      keepMs: 100_000,
    });
    for (let i = 0; i < 6; i++) {
      clock.t += 1000;
      const a = { key: `k${i}`, severity: 'warning' as const, text: `alarm ${i}` };
      centre.observe(laser, sum('idle', []), sum('alarm', [a]));
      centre.observe(laser, sum('alarm', [a]), sum('idle', []));
      const id = centre.query({ machines: null, state: 'unacknowledged' })[0]?.id ?? '';
      centre.acknowledge(id, 'olga');
    }
    expect(centre.query({ machines: null }).map((r) => r.key)).toEqual(['k5', 'k4', 'k3']);
    clock.t += 200_000;
    centre.observe(laser, sum('idle', []), sum('alarm', [FLAME]));
    expect(centre.query({ machines: null }).map((r) => r.key)).toEqual(['xtool-flame']);
  });

  it('keeps the list across a restart (a real file), and the restart does not lose open alarms', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const a = setup(t.dir);
    a.centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    a.centre.observe(cnc, sum('running', []), sum('alarm', [TILT]));
    a.centre.acknowledge(a.centre.query({ machines: null, machine: 'cnc-1' })[0]?.id ?? '', 'olga');
    await a.centre.close();
    const b = setup(t.dir);
    const keys = b.centre.query({ machines: null }).map((r) => [r.key, r.ackBy, r.clearedAt]);
    expect(keys).toEqual([
      ['xtool-flame', null, null],
      ['xtool-tilt', 'olga', null],
    ]);
    // The watch's first look after the restart clears what the controller no longer reports.
    b.centre.observe(laser, sum('unknown'), sum('idle', []));
    expect(b.centre.query({ machines: null, state: 'active' }).map((r) => r.key)).toEqual(['xtool-tilt']);
    // New ids continue after the old ones.
    b.centre.observe(laser, sum('idle', []), sum('alarm', [FLAME]));
    const ids = b.centre.query({ machines: null }).map((r) => Number(r.id));
    expect(new Set(ids).size).toBe(ids.length);
  });

  it('an unreadable list is set aside (never lost) and a new one started, with a log line', () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    writeFileSync(path.join(t.dir, 'alarms.json'), '{"version":1,"records":[{"id":');
    const s = setup(t.dir);
    expect(s.centre.query({ machines: null })).toEqual([]);
    expect(s.lines.join('\n')).toMatch(/alarm list could not be read/);
    expect(readdirSync(t.dir).some((f) => f.startsWith('alarms.json.unreadable-'))).toBe(true);
  });

  it('a write is a new file renamed over the old: a crash between writes leaves a whole list', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const s = setup(t.dir);
    s.centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    await s.centre.close();
    // A crash while the next write was under way leaves its temporary file behind.
    writeFileSync(path.join(t.dir, 'alarms.json.tmp'), '{"version":1,"seq":9,"rec');
    const again = setup(t.dir);
    expect(again.centre.query({ machines: null }).map((r) => r.key)).toEqual(['xtool-flame']);
    expect(existsSync(path.join(t.dir, 'alarms.json'))).toBe(true);
    expect(JSON.parse(readFileSync(path.join(t.dir, 'alarms.json'), 'utf8'))).toMatchObject({ version: 1 });
  });

  it('a record is on disk when it is announced: raised, cleared, acknowledged (finding 15)', () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const onDisk: Array<[AlarmEvent, AlarmRecord | undefined]> = [];
    const clock = { t: Date.parse('2026-11-25T03:00:00Z') };
    const log = createLogger({ write: () => undefined });
    const centre = new AlarmCentre({
      dataDir: t.dir,
      log,
      now: () => clock.t,
      // The announcement (the webhook, the audit): what would a restart right now find?
      onChange: (e, r) => onDisk.push([e, new AlarmCentre({ dataDir: t.dir, log }).get(r.id)]),
    });
    centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    const id = centre.query({ machines: null })[0]?.id ?? '';
    clock.t += 1000;
    centre.acknowledge(id, 'olga');
    clock.t += 1000;
    centre.observe(laser, sum('alarm', [FLAME]), sum('idle', []));
    expect(onDisk.map(([e, r]) => [e, r?.key, r?.ackBy ?? null, r?.clearedAt ?? null])).toEqual([
      ['alarm.raised', 'xtool-flame', null, null],
      ['alarm.acknowledged', 'xtool-flame', 'olga', null],
      ['alarm.cleared', 'xtool-flame', 'olga', clock.t],
    ]);
    // No snapshot was written yet (its timer did not run): the journal holds it all.
    expect(existsSync(path.join(t.dir, 'alarms.json'))).toBe(false);
  });

  it('the journal after a snapshot: only newer lines replay; a line cut short by a crash is skipped', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const a = setup(t.dir);
    a.centre.observe(laser, sum('running', []), sum('alarm', [FLAME]));
    await a.centre.close();
    // The snapshot holds everything: the journal is empty.
    expect(readFileSync(path.join(t.dir, 'alarms.journal'), 'utf8')).toBe('');
    const b = setup(t.dir);
    const id = b.centre.query({ machines: null })[0]?.id ?? '';
    b.centre.acknowledge(id, 'olga');
    b.centre.observe(cnc, sum('running', []), sum('alarm', [TILT]));
    // Killed before its snapshot, in the middle of a journal line.
    appendFileSync(path.join(t.dir, 'alarms.journal'), '{"v":99,"r":{"id":"7","mach');
    const c = setup(t.dir);
    expect(c.centre.query({ machines: null }).map((r) => [r.key, r.ackBy])).toEqual([
      ['xtool-flame', 'olga'],
      ['xtool-tilt', null],
    ]);
    expect(c.lines.join('\n')).toMatch(/recovered from the journal/);
  });

  it('a process killed with SIGKILL right after it announced a flame keeps the record (finding 15)', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const root = path.resolve(import.meta.dirname, '..');
    const tsx = pathToFileURL(path.join(root, 'node_modules', 'tsx', 'dist', 'loader.mjs')).href;
    const child = spawn(
      process.execPath,
      ['--import', tsx, path.join(import.meta.dirname, 'test-util-alarm-child.ts'), t.dir],
      {
        stdio: ['ignore', 'pipe', 'pipe'],
        env: { ...process.env, TSX_TSCONFIG_PATH: path.join(root, 'tsconfig.json') },
      },
    );
    const exited = new Promise<NodeJS.Signals | null>((r) => child.once('exit', (_c, sig) => r(sig)));
    let err = '';
    child.stderr.on('data', (d: Buffer) => (err += d.toString()));
    const announced = await new Promise<string>((resolve, reject) => {
      let out = '';
      child.stdout.on('data', (d: Buffer) => {
        out += d.toString();
        const m = /announced (\S+)\n/.exec(out);
        if (m?.[1]) resolve(m[1]);
      });
      void exited.then(() => reject(new Error(`the child exited before announcing: ${err}`)));
    });
    child.kill('SIGKILL');
    expect(await exited).toBe('SIGKILL');
    // Restarted: the record is there, unacknowledged and open.
    const again = setup(t.dir);
    expect(again.centre.get(announced)).toMatchObject({
      machine: 'laser-1',
      key: 'xtool-flame',
      severity: 'critical',
      clearedAt: null,
      ackAt: null,
    });
  }, 30_000);
});
