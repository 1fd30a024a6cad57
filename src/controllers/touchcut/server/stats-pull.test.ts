import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { createLogger } from '../../../../gateway/log';
import { consoleFetch, startGateway, tempDir } from '../../../../gateway/test-util';
import { addDays, localDay } from '../../../../gateway/history/shifts';
import { HistoryStore, jobCommandsOf } from '../../../../gateway/history/store';
import type { NodeFamily } from '../../../fleet/server-part';
import { touchcutFamily as touchcutDescriptor } from '../family';
import { touchcutServer } from '.';
import { BACKFILL_DAYS, TouchcutStatsPuller } from './stats-pull';

/** The family as src/controllers/families.ts lists it: with its server part. */
const touchcutFamily: NodeFamily = { ...touchcutDescriptor, server: touchcutServer };

/** TouchCut's daily statistics pulled into the history store. */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const DAY = { machine: [], machineResettable: [], sessions: [], consumables: [], units: 'metric' };

describe('TouchCut statistics puller', () => {
  it('stores each completed day once, as returned; refuses what the schema refuses; retries a failure', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const lines: string[] = [];
    const log = createLogger({ write: (l) => lines.push(l) });
    const clock = { now: new Date(2026, 2, 10, 9, 0).getTime() };
    const store = new HistoryStore({
      file: path.join(t.dir, 'h.sqlite'),
      log,
      now: () => clock.now,
      jobCommands: jobCommandsOf({}),
    });
    cleanups.push(() => store.close());
    const asked: string[] = [];
    let answer: (day: string) => { status: number; body: string; gateway?: boolean } = (day) => ({
      status: 200,
      body: JSON.stringify({
        ...DAY,
        sessions: [{ user: 'Op', startTime: `${day}T06:00:00`, activeTime: 3600 }],
      }),
    });
    const puller = new TouchcutStatsPuller({
      days: store.statsDays(),
      machines: [{ id: 't1', name: 'Plasma', kind: 'touchcut' }],
      read: (_m, p) => {
        asked.push(p);
        const day = new URLSearchParams(p.split('?')[1]).get('start-date') ?? '';
        return Promise.resolve(answer(day));
      },
      log,
      now: () => clock.now,
      backfillDays: 3,
    });
    expect(await puller.pullOnce()).toEqual({ stored: 3, failed: 0 });
    expect(asked).toEqual([
      '/rest/v1/stats?start-date=2026-03-07&end-before-date=2026-03-08&units=metric',
      '/rest/v1/stats?start-date=2026-03-08&end-before-date=2026-03-09&units=metric',
      '/rest/v1/stats?start-date=2026-03-09&end-before-date=2026-03-10&units=metric',
    ]);
    const days = store.touchcutDays({ machines: null });
    expect(days.map((d) => d.day)).toEqual(['2026-03-09', '2026-03-08', '2026-03-07']);
    expect(days[0]?.stats).toEqual({
      ...DAY,
      sessions: [{ user: 'Op', startTime: '2026-03-09T06:00:00', activeTime: 3600 }],
    });
    // Nothing new the same day.
    asked.length = 0;
    expect(await puller.pullOnce()).toEqual({ stored: 0, failed: 0 });
    expect(asked).toEqual([]);
    // The next day: the machine is off (the gateway's own failure), then answers garbage.
    clock.now += 86_400_000;
    answer = () => ({ status: 502, body: '{}', gateway: true });
    expect(await puller.pullOnce()).toEqual({ stored: 0, failed: 1 });
    expect(await puller.pullOnce()).toEqual({ stored: 0, failed: 1 });
    expect(lines.filter((l) => l.includes('TouchCut statistics not pulled'))).toHaveLength(1);
    answer = () => ({ status: 200, body: JSON.stringify({ machine: 'lots' }) });
    expect(await puller.pullOnce()).toEqual({ stored: 0, failed: 1 });
    answer = () => ({ status: 200, body: JSON.stringify(DAY) });
    expect(await puller.pullOnce()).toEqual({ stored: 1, failed: 0 });
    expect(store.touchcutDays({ machines: null, from: '2026-03-10' })).toMatchObject([
      { day: '2026-03-10', stats: DAY },
    ]);
  });

  it('pulls from a simulated TouchCut through the gateway, served by the API', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          {
            id: 'tc',
            name: 'Plasma',
            kind: 'touchcut',
            simulated: true,
            url: null,
            wsUrl: null,
            secrets: {},
          },
        ],
      },
      families: { touchcut: touchcutFamily },
      dataDir: t.dir,
      env: {},
    });
    cleanups.push(gw.close);
    const r = await gw.gw.history.pullStats();
    expect(r).toEqual({ stored: BACKFILL_DAYS, failed: 0 });
    const today = localDay(Date.now());
    const api = (await (await consoleFetch(`${gw.url}/api/history/touchcut-stats?machine=tc`)).json()) as {
      days: Array<{ machine: string; machineName: string; day: string; stats: { sessions?: unknown[] } }>;
    };
    expect(api.days).toHaveLength(BACKFILL_DAYS);
    expect(api.days[0]).toMatchObject({ machine: 'tc', machineName: 'Plasma', day: addDays(today, -1) });
    const csv = await (await consoleFetch(`${gw.url}/api/history/touchcut-stats.csv?machine=tc`)).text();
    const lines = csv.trim().split('\r\n');
    expect(lines[0]?.replace(/^\uFEFF/, '')).toBe(
      'machine,machine_name,day,sessions,active_s,productive_s,unproductive_s,error_s,idle_s,tool_on_s,programs,errors,pulled',
    );
    expect(lines).toHaveLength(BACKFILL_DAYS + 1);
    // The simulator's day: its sessions summed (seconds), its programs and errors counted.
    expect(lines[1]).toMatch(new RegExp(`^tc,Plasma,${addDays(today, -1)},\\d+,\\d+(\\.\\d+)?,`));
    expect(await gw.gw.history.pullStats()).toEqual({ stored: 0, failed: 0 });
  });
});
