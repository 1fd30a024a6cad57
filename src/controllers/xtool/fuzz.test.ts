import { describe, expect, it, vi } from 'vitest';
import type { z } from 'zod/mini';
import {
  FAKE_TIMERS,
  Findings,
  FuzzSimulator,
  Mutator,
  fixtureFiles,
  guarded,
  parseChecked,
  snapshotProblem,
  watchBoundary,
  type Mutant,
  type Seed,
  fuzzHarness,
  report,
} from '../../../tests/faults/fuzz';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { initialDetail, snapshotOf } from './model';
import { XtoolSession } from './session';
import { XtoolSimulator } from './sim/simulator';
import {
  INITIAL_STATE,
  alarmForFrame,
  applyFrame,
  applyPoll,
  jobSummary,
  stateLabel,
  type MachineState,
} from './state';
import * as wire from './wire';

// Pure CPU work: on a loaded 2-core machine a case takes 20–35 s; the time bound is not the test.
vi.setConfig({ testTimeout: 90_000 });

/**
 * Hostile input for the xTool family (issue 15): thousands of payloads mutated from the captures
 * in tests/fixtures/xtool, through every wire schema, the state machine, and a running session
 * (its polls and its status socket). Nothing may throw past the boundary, no `__proto__` key may
 * become a prototype, and the session stays alive. Seeded: a failure names its payload and replays.
 */

const SEED = 0x15_0001;

const HTTP = fixtureFiles('xtool/d-series/http', ['.json', '.txt']);
const OTHER = fixtureFiles('xtool/other-models', ['.json', '.txt']);
const DISCOVERY = fixtureFiles('xtool/discovery');
const FRAMES: Seed[] =
  (
    JSON.parse(fixtureFiles('xtool/d-series').find((f) => f.name === 'ws-frames.json')?.text ?? '{}') as {
      frames?: Array<{ frame: string }>;
    }
  ).frames?.map((f, i) => ({ name: `ws-frames.json#${i}`, text: f.frame })) ?? [];

function seedsOf(files: Array<{ name: string; text: string }>, match: RegExp): Seed[] {
  return files.filter((f) => match.test(f.name));
}

/** Each schema with the captures of its answer (and, now and then, another answer: wrong shapes). */
const TARGETS: Array<{ name: string; schema: z.ZodMiniType; seeds: Seed[] }> = [
  { name: 'ping', schema: wire.pingSchema, seeds: seedsOf(HTTP, /ping|result_/) },
  { name: 'progress', schema: wire.progressSchema, seeds: seedsOf(HTTP, /progress/) },
  { name: 'machine type', schema: wire.machineTypeSchema, seeds: seedsOf(HTTP, /getmachinetype/) },
  { name: 'laser power', schema: wire.laserPowerTypeSchema, seeds: seedsOf(HTTP, /getlaserpowertype/) },
  { name: 'laser power info', schema: wire.laserPowerInfoSchema, seeds: seedsOf(HTTP, /getlaserpowerinfo/) },
  {
    name: 'periphery',
    schema: wire.peripheryStatusSchema,
    seeds: seedsOf([...HTTP, ...OTHER], /peripherystatus/),
  },
  { name: 'mac', schema: wire.macSchema, seeds: seedsOf(HTTP, /=mac/) },
  { name: 'version', schema: wire.versionSchema, seeds: seedsOf([...HTTP, ...OTHER], /version/) },
  { name: 'working state', schema: wire.workingStaSchema, seeds: seedsOf(HTTP, /get_working_sta/) },
  { name: 'offset', schema: wire.offsetSchema, seeds: seedsOf(HTTP, /offset/) },
  { name: 'dot mode', schema: wire.dotModeSchema, seeds: seedsOf(HTTP, /dotMode/) },
  { name: 'device name', schema: wire.devNameSchema, seeds: seedsOf(HTTP, /get_dev_name/) },
  { name: 'result', schema: wire.resultSchema, seeds: seedsOf(HTTP, /result_/) },
  { name: 'file list', schema: wire.listSchema, seeds: seedsOf(HTTP, /GET_list/) },
  { name: 'upgrade reply', schema: wire.upgradeReplySchema, seeds: seedsOf(HTTP, /upgrade_response/) },
  { name: 'discovery reply', schema: wire.discoveryReplySchema, seeds: seedsOf(DISCOVERY, /reply/) },
  { name: 'discovery response', schema: wire.discoveryResponseSchema, seeds: seedsOf(DISCOVERY, /reply/) },
];
const ALL_SEEDS: Seed[] = [...HTTP, ...OTHER, ...DISCOVERY];

const { server } = fuzzHarness();

describe('xTool: hostile payloads through the parsers', () => {
  it('has seeds for every schema', () => {
    for (const t of TARGETS) expect(t.seeds.length, t.name).toBeGreaterThan(0);
    expect(FRAMES.length).toBeGreaterThan(5);
  });

  it('every wire schema and the vendor error parser: no exception, no prototype from a payload', () => {
    const mut = new Mutator(SEED);
    const findings = new Findings();
    let n = 0;
    for (let i = 0; i < 4000; i++) {
      const t = mut.rand.pick(TARGETS);
      const seed = mut.rand.chance(0.9) ? mut.rand.pick(t.seeds) : mut.rand.pick(ALL_SEEDS);
      const m = mut.mutate(seed);
      parseChecked(t.name, t.schema, m, findings);
      guarded('parseXtoolError', m, findings, () => {
        let body: unknown = null;
        try {
          body = JSON.parse(m.text);
        } catch {
          body = null;
        }
        return wire.parseXtoolError(200, body, m.text);
      });
      n++;
    }
    expect(n).toBe(4000);
    expect(findings.count, report(findings)).toBe(0);
  });

  it('frames and polls through the state machine and the snapshot: no exception', () => {
    const mut = new Mutator(SEED + 1);
    const findings = new Findings();
    let state: MachineState = INITIAL_STATE;
    let prev: z.output<typeof wire.progressSchema> | null = null;
    for (let i = 0; i < 3000; i++) {
      const m = mut.mutate(mut.rand.pick(FRAMES));
      const f = parseChecked('frame', wire.frameSchema, { ...m, text: JSON.stringify(m.text) }, findings);
      if (f?.success) {
        state = guarded('applyFrame', m, findings, () => applyFrame(state, f.data)) ?? state;
        guarded('alarmForFrame', m, findings, () => alarmForFrame(f.data, Date.now()));
        guarded('stateLabel', m, findings, () => stateLabel(state));
      }
      if (i % 3 === 0) {
        const pm = mut.mutate(mut.rand.pick(seedsOf(HTTP, /progress/)));
        const wm = mut.mutate(mut.rand.pick(seedsOf(HTTP, /get_working_sta/)));
        const p = parseChecked('progress', wire.progressSchema, pm, findings);
        const w = parseChecked('working state', wire.workingStaSchema, wm, findings);
        if (p?.success && w?.success) {
          const pd = p.data;
          const wd = w.data;
          state = guarded('applyPoll', pm, findings, () => applyPoll(state, wd.code, pd, prev)) ?? state;
          guarded('jobSummary', pm, findings, () => jobSummary(state, pd, null));
          const detail = { ...initialDetail(), machine: state, progress: pd, working: wd };
          const snap = guarded('snapshotOf', pm, findings, () => snapshotOf(detail));
          if (snap?.job) {
            const pr = snap.job.progress;
            if (pr !== null && !(Number.isFinite(pr) && pr >= 0 && pr <= 1))
              findings.add('snapshot', `job progress ${pr}`, pm);
          }
          prev = pd;
        }
      }
    }
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe('xTool: hostile payloads through a running session', () => {
  it('polls and socket frames: the session stays alive, nothing escapes, the snapshot stays sane', async () => {
    vi.useFakeTimers({ toFake: [...FAKE_TIMERS.toFake] });
    const id = 'fuzz-laser';
    const sim = new FuzzSimulator(new XtoolSimulator({ id, name: 'Fuzzed laser' }));
    server.use(...simulatorHandlers(id, sim));
    const ctx = createContext(
      { id, name: 'Fuzzed laser', kind: 'xtool', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const session = new XtoolSession(ctx);
    const findings = new Findings();
    let current: Mutant | string = 'connecting';
    const unwatch = watchBoundary(session.tracker, ctx.log, findings, () => current);
    const step = async (ms = 50) => {
      await vi.advanceTimersByTimeAsync(ms);
    };
    try {
      session.start();
      for (let t = 0; t < 400 && !(ctx.snapshot.getState().link === 'online' && sim.socketsOpen > 0); t++)
        await step();
      expect(ctx.snapshot.getState().link).toBe('online');
      expect(sim.socketsOpen).toBeGreaterThan(0);
      const mut = new Mutator(SEED + 2);
      const check = (m: Mutant) => {
        const p = snapshotProblem(ctx.snapshot.getState());
        if (p) findings.add('snapshot', p, m);
        if (!session.started) findings.add('session', 'the session stopped', m);
      };

      // Frames into the status socket, as the laser would send them.
      for (let i = 0; i < 1500; i++) {
        const m = mut.mutate(mut.rand.pick(FRAMES));
        current = m;
        guarded('socket frame', m, findings, () => sim.sendFrame(m.text));
        if (i % 25 === 0) await step(10);
        check(m);
      }
      await step(100);
      // The frames reached the session (a test that cannot fail is worse than none).
      const unknown = ctx.log.store.getState().entries.filter((e) => e.text.startsWith('Unknown frame'));
      expect(unknown.length).toBeGreaterThan(100);

      // Poll answers: get_working_sta and /progress, one mutated answer per poll.
      const pollTargets = [
        {
          match: (_m: string, p: string) => p.startsWith('/system?action=get_working_sta'),
          seeds: seedsOf(HTTP, /get_working_sta/),
        },
        { match: (_m: string, p: string) => p.startsWith('/progress'), seeds: seedsOf(HTTP, /progress/) },
      ];
      const seen = new Set<string>();
      for (let i = 0; i < 150; i++) {
        const t = mut.rand.pick(pollTargets);
        const m = mut.mutate(mut.rand.pick(t.seeds));
        current = m;
        sim.answerNext(t.match, m);
        const served = sim.served;
        session.kick();
        for (let k = 0; k < 200 && sim.served === served; k++) await step(100);
        await step(20);
        check(m);
        seen.add(ctx.snapshot.getState().link);
      }
      expect(sim.served).toBeGreaterThan(100);
      // Refused payloads showed as protocol errors, good ones brought the machine back.
      expect(seen).toContain('protocol-error');
      expect(seen).toContain('online');
      expect(session.started).toBe(true);
    } finally {
      unwatch();
      session.stop();
      sim.dispose();
    }
    expect(findings.count, report(findings)).toBe(0);
  }, 90_000);
});
