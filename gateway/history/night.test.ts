import { afterEach, describe, expect, it } from 'vitest';
import type { WatchSummary } from '../../src/fleet/contract';
import type { MachineEntry } from '../machines';
import { families } from '../../src/controllers/families';
import { consoleFetch, startGateway, tempDir, testFamily as bareTestFamily } from '../test-util';
import { S } from './summary.test-util';

/** A test family of `kind` with that family's job commands (the history reads them from the families). */
const testFamily = (kind: MachineEntry['kind']) => ({ ...bareTestFamily(kind), jobs: families[kind].jobs });

/**
 * A simulated night through the real gateway on a fake clock: three machines run, pause, raise
 * alarms and go offline as their watch would report it, and the Night shift's report (22:00–06:00,
 * the server's local time) adds up to the simulated durations to the second.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

/** Local time on the 10th (day 0) or the 11th (day 1) of March 2026. */
const at = (day: 0 | 1, hh: number, mm: number, ss = 0): number =>
  new Date(2026, 2, 10 + day, hh, mm, ss).getTime();

type Step = [number, WatchSummary] | [number, 'command', string, string];

describe('a simulated night', () => {
  it('the Night shift report sums to the simulated durations, to the second', async () => {
    const clock = { now: at(0, 20, 0) };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const entry = (id: string, name: string, kind: MachineEntry['kind']): MachineEntry => ({
      id,
      name,
      kind,
      simulated: true,
      url: null,
      wsUrl: null,
      secrets: {},
    });
    const machines = [
      entry('laser', 'Laser', 'xtool'),
      entry('router', 'Router', 'g2core'),
      entry('printer', 'Printer', 'duet'),
    ];
    const gw = await startGateway({
      machines: { file: null, machines },
      families: { xtool: testFamily('xtool'), g2core: testFamily('g2core'), duet: testFamily('duet') },
      dataDir: t.dir,
      env: {},
      now: () => clock.now,
    });
    cleanups.push(gw.close);
    const history = gw.gw.history;

    const script: Record<string, Step[]> = {
      laser: [
        [at(0, 21, 0), S('idle')],
        [at(0, 22, 30, 10), 'command', 'xtool.run-file', 'otto'],
        [at(0, 22, 30, 17), S('running', { job: 'bracket.nc', progress: 0 })],
        [at(0, 23, 15), S('paused', { job: 'bracket.nc', progress: 0.4 })],
        [at(0, 23, 20), S('running', { job: 'bracket.nc', progress: 0.4 })],
        [at(1, 1, 0), S('idle', { job: 'bracket.nc', progress: 1 })],
        [at(1, 2, 0), S('running', { job: 'plate.nc' })],
        [at(1, 2, 30), S('alarm', { alarm: 'Flame detected', job: 'plate.nc' })],
        [at(1, 2, 45), S('idle')],
      ],
      router: [
        [at(0, 21, 30), S('running', { job: 'long.gcode' })],
        [at(1, 3, 0), S('offline', { job: 'long.gcode' })],
        [at(1, 3, 30), S('running', { job: 'long.gcode' })],
        [at(1, 5, 0), S('idle')],
        [at(1, 6, 30), S('running', { job: 'morning.gcode' })],
      ],
      printer: [
        [at(0, 22, 10), S('idle')],
        [at(0, 23, 0), S('alarm', { alarm: 'Emergency stop' })],
        [at(0, 23, 10, 30), S('idle')],
        [at(1, 3, 59, 58), 'command', 'duet.start', 'otto'],
        [at(1, 4, 0), S('running', { job: 'night-run.gcode' })],
        [at(1, 5, 30), 'command', 'duet.cancel', 'sam'],
        [at(1, 5, 30, 4), S('idle')],
        [at(1, 5, 45), S('running', { job: 'next.gcode' })],
      ],
    };
    // Every step of every machine in time order, as the watches and the proxy would deliver them.
    const events = Object.entries(script)
      .flatMap(([id, steps]) => steps.map((s) => ({ id, s })))
      .sort((a, b) => a.s[0] - b.s[0]);
    const last = new Map<string, WatchSummary>();
    let nextBeat = clock.now;
    for (const { id, s } of events) {
      // The heartbeat every 5 s, as the timer runs it.
      for (; nextBeat < s[0]; nextBeat += 5000) {
        clock.now = nextBeat;
        history.store?.heartbeat();
      }
      clock.now = s[0];
      const m = machines.find((x) => x.id === id);
      if (!m) throw new Error(id);
      if (s[1] === 'command') {
        history.recorded({
          type: 'command',
          result: 'ok',
          source: 'gateway',
          machine: id,
          commandId: s[2],
          user: s[3],
        });
        continue;
      }
      history.observe(m, last.get(id) ?? S('unknown'), s[1]);
      last.set(id, s[1]);
    }
    clock.now = at(1, 7, 0);

    const r = await consoleFetch(`${gw.url}/api/history/shift-report?date=2026-03-10&shift=Night`);
    expect(r.status).toBe(200);
    const report = (await r.json()) as {
      from: number;
      to: number;
      spanS: number;
      shift: { name: string };
      machines: Array<{ machine: string; seconds: Record<string, number>; jobs: Record<string, number> }>;
      totals: { seconds: Record<string, number>; jobs: Record<string, number> };
    };
    expect(report).toMatchObject({
      from: at(0, 22, 0),
      to: at(1, 6, 0),
      spanS: 8 * 3600,
      shift: { name: 'Night' },
    });
    const of = (id: string) => report.machines.find((m) => m.machine === id);
    // laser: idle 22:00–22:30:17, 01:00–02:00, 02:45–06:00; running 22:30:17–23:15, 23:20–01:00,
    // 02:00–02:30; paused 23:15–23:20; alarm 02:30–02:45.
    expect(of('laser')).toMatchObject({
      seconds: {
        running: 2683 + 6000 + 1800,
        paused: 300,
        idle: 1817 + 3600 + 11700,
        alarm: 900,
        offline: 0,
        unknown: 0,
        unrecorded: 0,
      },
      jobs: { finished: 1, failed: 1, cancelled: 0, unknown: 0, inProgress: 0 },
    });
    // router: running since 21:30 to 03:00, offline 03:00–03:30, running to 05:00, idle to 06:00.
    // Its job went out of sight and came back idle: unknown.
    expect(of('router')).toMatchObject({
      seconds: { running: 18000 + 5400, offline: 1800, idle: 3600, paused: 0, alarm: 0, unrecorded: 0 },
      jobs: { unknown: 1, finished: 0, inProgress: 0 },
    });
    // printer: first seen 22:10 (unrecorded before), e-stop 23:00–23:10:30, a job 04:00–05:30:04
    // stopped by a supervisor, another from 05:45 still running at 06:00.
    expect(of('printer')).toMatchObject({
      seconds: { unrecorded: 600, idle: 3000 + 17370 + 896, alarm: 630, running: 5404 + 900, paused: 0 },
      jobs: { cancelled: 1, inProgress: 1, finished: 0 },
    });
    expect(report.totals.seconds).toEqual({
      running: 10483 + 23400 + 6304,
      paused: 300,
      idle: 17117 + 3600 + 21266,
      alarm: 1530,
      offline: 1800,
      unknown: 0,
      unrecorded: 600,
    });
    expect(Object.values(report.totals.seconds).reduce((a, b) => a + b, 0)).toBe(3 * 8 * 3600);

    // The jobs of the night, newest first, with who and how long.
    const jobs = (await (
      await consoleFetch(`${gw.url}/api/history/jobs?from=${at(0, 22, 0)}&to=${at(1, 6, 0)}`)
    ).json()) as {
      jobs: Array<Record<string, unknown>>;
      total: number;
    };
    expect(jobs.total).toBe(5);
    const job = (name: string) => jobs.jobs.find((j) => j['name'] === name);
    expect(job('bracket.nc')).toMatchObject({
      machine: 'laser',
      machineName: 'Laser',
      family: 'xtool',
      outcome: 'finished',
      startedAt: at(0, 22, 30, 17),
      endedAt: at(1, 1, 0),
      runningS: 8683,
      pausedS: 300,
      progress: 1,
      startedBy: 'otto',
    });
    expect(job('plate.nc')).toMatchObject({ outcome: 'failed', endAlarm: 'Flame detected', runningS: 1800 });
    expect(job('long.gcode')).toMatchObject({
      outcome: 'unknown',
      runningS: 19800 + 5400,
      startedAt: at(0, 21, 30),
    });
    expect(job('night-run.gcode')).toMatchObject({
      outcome: 'cancelled',
      startedBy: 'otto',
      stoppedBy: 'sam',
      runningS: 5404,
    });
    expect(job('next.gcode')).toMatchObject({ outcome: null, endedAt: null, runningS: 75 * 60 });

    const stops = (await (
      await consoleFetch(`${gw.url}/api/history/stops?from=${at(0, 22, 0)}&to=${at(1, 6, 0)}`)
    ).json()) as {
      stops: unknown[];
    };
    expect(stops.stops).toEqual([
      { alarm: 'Flame detected', count: 1, seconds: 900, machines: ['laser'] },
      { alarm: 'Emergency stop', count: 1, seconds: 630, machines: ['printer'] },
    ]);

    // The Early shift of the 11th: 06:00–14:00, up to now (07:00).
    const early = (await (
      await consoleFetch(`${gw.url}/api/history/shift-report?date=2026-03-11&shift=Early`)
    ).json()) as {
      spanS: number;
      machines: Array<{ machine: string; seconds: Record<string, number> }>;
    };
    expect(early.spanS).toBe(3600);
    expect(early.machines.find((m) => m.machine === 'router')?.seconds).toMatchObject({
      idle: 1800,
      running: 1800,
    });
  });
});
