import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import { g2coreAccess } from './access';
import { g2coreDeclaration } from './declaration';
import { JOBS_STALE_MS } from './queries';
import { SLOW_POLL_MS, SR_POLL_MS } from './session';
import { g2coreShareRead, g2coreSharing, g2coreWatch, readStatusReport } from './sharing';

const FIX = join(process.cwd(), 'tests/fixtures/g2core');
const text = (rel: string) => readFileSync(join(FIX, rel), 'utf8');

/** `{"sr":{…}}` lines a real board sent (what a REST server may pass through). */
function srLines(rel: string): string[] {
  return text(rel)
    .split('\n')
    .filter((l) => l.trim() !== '')
    .map((l) => JSON.parse(l) as { dir: string; raw: string })
    .filter((l) => l.dir === 'rx' && l.raw.startsWith('{"sr"'))
    .map((l) => l.raw);
}

/** Path and query as the gateway hands them over (its canonical split). */
function target(raw: string): { path: string; query: URLSearchParams } {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { path: t.path, query: t.query };
}
const share = (raw: string) => {
  const t = target(raw);
  return g2coreShareRead(t.path, t.query);
};
const filter = (f: unknown) => `filter=${encodeURIComponent(JSON.stringify(f))}`;

const GETS = [
  '/version',
  '/machine',
  '/machine?shallow=true',
  `/machine?${filter({ x: { am: null }, mfoe: null, ssoe: null })}`,
  '/machine/xvm',
  '/machine/ct',
  '/machine/clear',
  '/machine/clr',
  '/machine/sys/clear',
  '/machine/SYS.CLEAR',
  '/machine/alarm',
  '/machine/shutd',
  '/machine/panic',
  '/status_report',
  `/status_report?${filter({ posx: 10, stat: null })}`,
  `/status_report?${filter({ clear: null })}`,
  `/status_report?${filter({ stat: null, sys: { alarm: null } })}`,
  `/status_report?${filter({ gc: 'G0 X1' })}`,
  `/status_report?filter=${encodeURIComponent('{clear:n}')}`,
  `/machine?${filter({ panic: null })}`,
  '/operation',
  '/operation/42',
  '/job',
  '/job/7',
];

describe('g2core sharing: the declaration', () => {
  it('is what the declaration gives the gateway', () => {
    expect(g2coreDeclaration.gateway?.sharing).toBe(g2coreSharing);
    expect(g2coreSharing.keepAlive).toBe(true);
    expect(g2coreSharing.maxConcurrentReads).toBe(2);
    expect(g2coreSharing.streams).toBeUndefined();
  });
});

describe('g2core sharing: reads', () => {
  it('never shares a GET the access policy calls a command', () => {
    const commands = GETS.filter((raw) => g2coreAccess({ method: 'GET', ...target(raw) }).command);
    expect(commands.length).toBeGreaterThanOrEqual(11);
    for (const raw of commands) expect(share(raw), raw).toBeNull();
  });

  it('shares the status report at its poll period, the job list and operations at the jobs staleness', () => {
    expect(share('/status_report')).toBe(SR_POLL_MS);
    expect(share(`/status_report?${filter({ posx: 10, posy: 0, stat: 5, vel: 0 })}`)).toBe(SR_POLL_MS);
    expect(share('/job')).toBe(JOBS_STALE_MS);
    expect(share('/operation')).toBe(JOBS_STALE_MS);
    expect(share('/operation/42')).toBe(JOBS_STALE_MS);
    expect(JOBS_STALE_MS).toBeLessThanOrEqual(SLOW_POLL_MS);
    const shared = GETS.filter((raw) => share(raw) !== null);
    expect(shared).toEqual([
      '/status_report',
      `/status_report?${filter({ posx: 10, stat: null })}`,
      '/operation',
      '/operation/42',
      '/job',
    ]);
  });

  it('shares only the form the console sends', () => {
    for (const raw of [
      '/status_report?x=1',
      `/status_report?${filter({ stat: null })}&x=1`,
      '/Status_Report',
      '/status_report/',
      '/job?x=1',
      '/job/',
      '/operation/42/x',
    ])
      expect(share(raw), raw).toBeNull();
  });
});

describe('g2core sharing: the watch', () => {
  it('polls a full status report every 10 s', () => {
    expect(g2coreWatch.poll?.path).toBe('/status_report');
    expect(g2coreWatch.everyMs).toBe(10_000);
    expect(g2coreWatch.stream).toBeUndefined();
  });

  it('reads the design example and real status reports', () => {
    expect(readStatusReport(200, text('rest-design-examples/GET-status_report.json'))).toEqual({
      state: 'running',
      alarm: null,
      job: null,
      alarms: [],
    });
    const sr = srLines('sessions/g0-move-filtered-sr-101.03.jsonl');
    expect(sr.length).toBeGreaterThan(0);
    // the first carries stat 5 (run); the others no stat: unknown, never an error
    expect(readStatusReport(200, sr[0] as string)).toMatchObject({ state: 'running' });
    for (const l of sr.slice(1)) expect(readStatusReport(200, l)).not.toBeInstanceOf(Error);
  });

  it('reads the stopping states as alarms in words', () => {
    expect(readStatusReport(200, '{"stat":2}')).toEqual({
      state: 'alarm',
      alarm: expect.stringMatching(/^ALARM/),
      job: null,
      alarms: [{ key: 'g2core-alarm', severity: 'critical', text: expect.stringMatching(/^ALARM/) }],
    });
    expect(readStatusReport(200, '{"stat":12}')).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/^SHUTDOWN/),
    });
    expect(readStatusReport(200, '{"stat":13}')).toMatchObject({
      state: 'alarm',
      alarm: expect.stringMatching(/^PANIC/),
      alarms: [{ key: 'g2core-panic', severity: 'critical', text: expect.stringMatching(/^PANIC/) }],
    });
    expect(readStatusReport(200, '{"stat":11}')).toMatchObject({
      state: 'paused',
      alarm: expect.stringMatching(/interlock/i),
    });
    expect(readStatusReport(200, '{"stat":6}')).toEqual({
      state: 'paused',
      alarm: null,
      job: null,
      alarms: [],
    });
    expect(readStatusReport(200, '{"stat":"4"}')).toEqual({
      state: 'idle',
      alarm: null,
      job: null,
      alarms: [],
    });
  });

  it('turns error answers and garbage into an Error, never a throw', () => {
    for (const [status, body] of [
      [410, '{"status":{"code":204,"description":"Command rejected by ALARM"}}'],
      [200, '{"status":{"code":100,"description":"Unrecognized command or config name"}}'],
      [500, ''],
      [200, 'not json'],
      [200, '[1,2]'],
      [200, '{"posx":{"a":1}}'],
    ] as const)
      expect(readStatusReport(status, body), body).toBeInstanceOf(Error);
  });
});
