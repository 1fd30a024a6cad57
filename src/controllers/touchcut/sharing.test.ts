import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import { touchcutAccess } from './access';
import { touchcutDeclaration } from './declaration';
import { MONITOR_INTERVAL_MS, SCREENSHOT_MIN_GAP_MS } from './feeds';
import { PROGRAMS_REFRESH_MS } from './queries';
import { STATUS_INTERVAL_MS } from './session';
import { MANUAL_ERROR_BODIES, MANUAL_STATUS_TEXT } from './sim/data/manual';
import { readTouchcutStatus, touchcutShareRead, touchcutSharing, touchcutWatch } from './sharing';

/**
 * No real TouchCut answer exists anywhere (fixtures/touchcut/SOURCES.md): the status bodies here
 * are the manual's example (repaired where its text extraction broke an escape) and variations
 * of it written from the manual's template.
 */
const MANUAL_STATUS = MANUAL_STATUS_TEXT.replace('(0.394\\)', '(0.394\\")');
const status = (patch: Record<string, unknown>) =>
  JSON.stringify({ ...(JSON.parse(MANUAL_STATUS) as Record<string, unknown>), ...patch });

/** Path and query as the gateway hands them over (its canonical split). */
function target(raw: string): { path: string; query: URLSearchParams } {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { path: t.path, query: t.query };
}
const share = (raw: string) => {
  const t = target(raw);
  return touchcutShareRead(t.path, t.query);
};

describe('TouchCut sharing: the declaration', () => {
  it('is what the declaration gives the gateway, beside the key and the held login', () => {
    expect(touchcutDeclaration.gateway?.sharing).toBe(touchcutSharing);
    expect(touchcutDeclaration.gateway?.injectSecrets).toBeDefined();
    expect(touchcutSharing.keepAlive).toBe(true);
    expect(touchcutSharing.maxConcurrentReads).toBe(3);
    expect(touchcutSharing.streams).toBeUndefined();
  });
});

describe('TouchCut sharing: reads', () => {
  it('shares every polled read with the period the console polls it', () => {
    expect(share('/rest/v1/status')).toBe(STATUS_INTERVAL_MS);
    expect(share('/rest/v1/status?units=metric')).toBe(STATUS_INTERVAL_MS);
    expect(share('/rest/v1/monitor?fields=axes.*%2Cio.din&units=imperial')).toBe(MONITOR_INTERVAL_MS);
    expect(share('/rest/v1/screenshot')).toBe(SCREENSHOT_MIN_GAP_MS);
    expect(share('/rest/v1/programs?offset=0&limit=25')).toBe(PROGRAMS_REFRESH_MS);
    expect(share('/rest/v1/unloader?history=true&start-date=2026-01-01&end-before-date=2026-01-02')).toBe(
      PROGRAMS_REFRESH_MS,
    );
    expect(share('/rest/v1/machine-info')).toBe(60_000);
    // the path form the access rule uses: any letter case, repeated and trailing slashes
    expect(share('/REST/v1/Status/')).toBe(STATUS_INTERVAL_MS);
  });

  it('shares no on-demand read, no "only what changed", no unknown parameter', () => {
    for (const raw of [
      '/rest/v1/stats?start-date=2026-01-01&end-before-date=2026-01-08',
      '/rest/v1/programs?offset=0&limit=25&onlyChangedData=true',
      '/rest/v1/programs?displayingProgramFileId=3',
      '/rest/v1/status?x=1',
      '/rest/v1/screenshot?t=1',
      '/rest/v1/machine-info?units=metric',
      '/rest/v1/auth',
      '/rest/v1/status%2F..',
      '/rest/v2/status',
      '/status',
    ])
      expect(share(raw), raw).toBeNull();
  });

  it('never shares what the access policy does not give every viewer as a read', () => {
    const gets = [
      '/rest/v1/auth',
      '/rest/v1/auth/change-password',
      '/rest/v1/unloader/move',
      '/rest/v1/settings',
      '/rest/v1/status',
      '/index.html',
      '/',
    ];
    const notReads = gets.filter((raw) => {
      const d = touchcutAccess({ method: 'GET', ...target(raw) });
      return d.command || d.role !== 'viewer';
    });
    expect(notReads.length).toBeGreaterThanOrEqual(4);
    for (const raw of notReads) expect(share(raw), raw).toBeNull();
  });
});

describe('TouchCut sharing: the watch', () => {
  it('polls the status every 5 s (no socket; a table that cuts with fire)', () => {
    expect(touchcutWatch.poll?.path).toBe('/rest/v1/status');
    expect(touchcutWatch.everyMs).toBe(5000);
    expect(touchcutWatch.stream).toBeUndefined();
    expect(touchcutDeclaration.gateway?.injectSecrets).toBeDefined();
  });

  it("reads the manual's example", () => {
    expect(readTouchcutStatus(200, MANUAL_STATUS)).toEqual({
      state: 'idle',
      alarm: null,
      job: null,
      alarms: [],
      progress: null,
    });
  });

  it('reads a cut, a pause, an e-stop and the messages', () => {
    expect(
      readTouchcutStatus(
        200,
        status({ machineState: 'Cutting', programName: 'bracket.nc', programProgress: 40 }),
      ),
    ).toEqual({ state: 'running', alarm: null, job: 'bracket.nc', alarms: [], progress: 0.4 });
    expect(
      readTouchcutStatus(200, status({ machineState: 'Feed Hold', programName: 'bracket.nc' })),
    ).toMatchObject({
      state: 'paused',
    });
    expect(readTouchcutStatus(200, status({ machineState: 'E-Stop' }))).toMatchObject({ state: 'alarm' });
    expect(
      readTouchcutStatus(
        200,
        status({ msgStatus: [{ key: 'torchCollision', msg: 'Torch collision detected' }] }),
      ),
    ).toEqual({
      state: 'alarm',
      alarm: 'Torch collision detected',
      job: null,
      alarms: [expect.objectContaining({ severity: 'critical', text: 'Torch collision detected' })],
      progress: null,
    });
    expect(
      readTouchcutStatus(200, status({ msgStatus: [{ key: 'consumables', msg: 'Electrode life low' }] })),
    ).toEqual({
      state: 'idle',
      alarm: 'Electrode life low',
      job: null,
      alarms: [expect.objectContaining({ severity: 'warning', text: 'Electrode life low' })],
      progress: null,
    });
  });

  it('turns failures and garbage into an Error, never a throw', () => {
    for (const [code, body] of [
      [401, ''],
      [401, '{"code":"401","msg":"Unauthorized"}'],
      [200, MANUAL_ERROR_BODIES.notReady],
      [500, MANUAL_STATUS],
      [200, MANUAL_STATUS_TEXT], // verbatim: an invalid escape
      [200, '<html>'],
      [200, '[]'],
      [200, '{"msgStatus":{"a":1}}'],
    ] as const)
      expect(readTouchcutStatus(code, body), `${code} ${body.slice(0, 30)}`).toBeInstanceOf(Error);
  });
});
