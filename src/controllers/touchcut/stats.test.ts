import { setupServer } from 'msw/node';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { simulatorHandlers } from '../../fleet/msw';
import { TouchcutClient } from './client';
import { SIM_LOG_DAYS, SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { addDays, daysIn, simDay } from './sim/statsgen';
import { consumableTotals, presetRange, sessionsByUser, toolTotalsOfSessions, totalsRows } from './stats';
import { viaGateway } from './testkit';

const NOW = Date.parse('2026-03-18T12:00:00Z'); // a Wednesday
const sim = new TouchcutSimulator({ id: 'st', name: 'Stats', now: () => NOW });
const server = setupServer(...simulatorHandlers('st', viaGateway(sim, SIM_MONITOR_API_KEY)));
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => {
  server.close();
  sim.dispose();
});
const client = new TouchcutClient('st');
/** First logged day: tomorrow minus the logging range (manual: default start-date). */
const FIRST = addDays('2026-03-19', -SIM_LOG_DAYS);

describe('touchcut stats maths against the simulator', () => {
  it('per-user time and consumable totals equal the sum of the simulated days', async () => {
    const range = presetRange('lastWeek', '2026-03-18');
    expect(range).toEqual({ startDate: '2026-03-09', endBeforeDate: '2026-03-16' });
    const stats = await client.stats(range);
    const days = daysIn(range.startDate, range.endBeforeDate).map(simDay);
    expect(stats.periods.map((p) => p.date)).toEqual(days.map((d) => d.date));

    const users = sessionsByUser(stats.sessions);
    const expectActive = new Map<string, number>();
    for (const d of days)
      for (const s of d.sessions) expectActive.set(s.user, (expectActive.get(s.user) ?? 0) + s.activeTime);
    expect(new Map(users.map((u) => [u.user, u.activeTime]))).toEqual(expectActive);
    for (const u of users) {
      // The simulator splits active time exactly: nothing is left as "other".
      expect(u.productiveTime + u.unproductiveTime + u.errorTime + u.idleTime).toBe(u.activeTime);
      expect(u.otherTime).toBe(0);
    }

    const cons = consumableTotals(stats.consumables);
    const electrodes = cons.filter((c) => c.consType === 'Electrode');
    const expectedPierces = days
      .flatMap((d) => d.consumables)
      .filter((c) => c.consType === 'Electrode')
      .reduce((n, c) => n + c.pierces, 0);
    expect(electrodes.reduce((n, c) => n + c.pierces, 0)).toBe(expectedPierces);
    // Each electrode sees exactly the plasma tool's cut of the sessions it was used in.
    const plasma = toolTotalsOfSessions(stats.sessions).find((t) => t.name === 'Plasma');
    expect(plasma?.starts).toBe(expectedPierces);
    expect(electrodes.reduce((n, c) => n + c.distance, 0)).toBeCloseTo(plasma?.distance ?? -1, 3);
  });

  it('a range is the sum of its parts, and the machine clips it to its logging range', async () => {
    const a = await client.stats({ startDate: '2026-03-01', endBeforeDate: '2026-03-08' });
    const b = await client.stats({ startDate: '2026-03-08', endBeforeDate: '2026-03-15' });
    const ab = await client.stats({ startDate: '2026-03-01', endBeforeDate: '2026-03-15' });
    const pierces = (s: typeof a) => consumableTotals(s.consumables).reduce((n, c) => n + c.pierces, 0);
    expect(pierces(a) + pierces(b)).toBe(pierces(ab));
    expect(ab.programs.length).toBe(a.programs.length + b.programs.length);

    const clipped = await client.stats({ startDate: '2020-01-01', endBeforeDate: '2030-01-01' });
    expect(clipped.periods[0]?.date).toBe(FIRST);
    expect(clipped.periods).toHaveLength(SIM_LOG_DAYS);
    expect(clipped.periods.at(-1)?.date).toBe('2026-03-18');
  });

  it('machine totals and resettable totals are consistent, condensed drops zero records, imperial converts', async () => {
    const full = await client.stats({ startDate: '2026-03-14', endBeforeDate: '2026-03-16' });
    const plasma = full.machine.find((t) => t.name === 'Plasma');
    const reset = full.machineResettable.find((t) => t.name === 'Plasma');
    expect((plasma?.time ?? 0) - (reset?.time ?? 0)).toBe(3_600_000);
    expect(reset?.lastReset).toBe(`${FIRST}T00:00:00`);
    expect(totalsRows(full.machine).filter((r) => r.carriage === 'all').length).toBe(2);

    const wide = { startDate: '2026-03-01', endBeforeDate: '2026-03-16' };
    const all = await client.stats(wide);
    const condensed = await client.stats({ ...wide, condensed: true });
    const emptyDays = daysIn(wide.startDate, wide.endBeforeDate)
      .map(simDay)
      .filter((d) => d.sessions.length + d.programs.length + d.errors.length === 0).length;
    expect(emptyDays).toBeGreaterThan(0);
    expect(all.periods).toHaveLength(15);
    expect(condensed.periods).toHaveLength(15 - emptyDays);
    const zero = (t: { time?: number; distance?: number; starts?: number; errors?: number }) =>
      !t.time && !t.distance && !t.starts && !t.errors;
    expect(condensed.sessions.flatMap((x) => x.toolTotals).some(zero)).toBe(false);
    const metric = await client.stats({
      startDate: '2026-03-09',
      endBeforeDate: '2026-03-10',
      units: 'metric',
    });
    const imperial = await client.stats({
      startDate: '2026-03-09',
      endBeforeDate: '2026-03-10',
      units: 'imperial',
    });
    expect(imperial.units).toBe('imperial');
    expect(imperial.consumables[0]?.distance).toBeCloseTo((metric.consumables[0]?.distance ?? 0) / 25.4, 1);
  });
});
