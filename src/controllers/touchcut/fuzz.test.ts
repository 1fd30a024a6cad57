import { describe, expect, it, vi } from 'vitest';
import type { z } from 'zod/mini';
import {
  FAKE_TIMERS,
  Findings,
  FuzzSimulator,
  MARKUP,
  Mutator,
  EXCEPTION_WORDS,
  VERY_DEEP,
  captureUncaught,
  deepText,
  fixtureFiles,
  foreignPrototype,
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
import { emptySnapshot } from '../../fleet/types';
import { parseTouchcutError } from './client';
import { credentialsOf, jwtExpiry, LOGIN_PATH, tokenOf, withoutToken } from './gateway';
import { identityOf, snapshotPatch, type JobClock } from './normalize';
import { mergeChanged } from './queries';
import { TouchcutSession } from './session';
import { readTouchcutStatus, touchcutShareRead } from './sharing';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { authFromHeld } from './state';
import { consumableTotals, programCounts, sessionsByUser, toolTotalsOfSessions, totalsRows } from './stats';
import { viaGateway } from './testkit';
import * as wire from './wire';

// Pure CPU work: on a loaded 2-core machine a case takes 20–35 s; the time bound is not the test.
vi.setConfig({ testTimeout: 90_000 });

/**
 * Hostile input for the TouchCut family (issue 15). No real capture of TouchCut exists
 * (tests/fixtures/touchcut/SOURCES.md), so the seeds are the simulator's answers to every read the
 * console makes (status in several states, machine-info, monitor, stats, programs, unloader, the
 * gateway's login answer) and the manual's failure bodies. Thousands of payloads mutated from them
 * go through the wire schemas and what reads their output (normalize, stats, the watch, the merge
 * of changed programs data, the gateway's login hooks), and through a running session (status,
 * monitor, machine-info, screen, login state, programs and stats reads). Nothing may throw past
 * the boundary, no `__proto__` key may become a prototype, and the session stays alive.
 * Seeded: a failure names its payload and replays.
 */

const SEED = 0x15_0005;

/** Captures in tests/fixtures/touchcut (none yet: SOURCES.md); fuzzed too once there are. */
const CAPTURED = fixtureFiles('touchcut', ['.json']);

/** The manual's "Failure Responses" and the auth answer, as printed (tests/fixtures has none). */
const MANUAL: Seed[] = [
  {
    name: 'manual: auth',
    text: '{ "success": "true", "token": "eyJhbGciOiJIUzI1NiJ9.eyJleHAiOjE5MDAwMDAwMDB9.c2ln" }',
  },
  { name: 'manual: 1003', text: '{ "code": "1003", "msg": "Required parameter missing: username" }' },
  { name: 'manual: 100', text: '{ "code": "100", "msg": "Application not ready" }' },
  { name: 'manual: 102', text: '{ "code": "102", "msg": "Invalid Password" }' },
  { name: 'manual: 2000', text: '{ "code":"2000", "msg":"Error creating JWT" }' },
];

interface Seeds {
  status: Seed[];
  info: Seed[];
  monitor: Seed[];
  stats: Seed[];
  programs: Seed[];
  unloader: Seed[];
  login: Seed[];
}

/** The simulator's answers to the console's reads (through the gateway stand-in, with the key). */
async function simSeeds(): Promise<Seeds> {
  const sim = new TouchcutSimulator({ id: 'seed', name: 'Seed TouchCut', tickMs: 100 });
  sim.autoOperator = false;
  const gw = viaGateway(sim, SIM_MONITOR_API_KEY);
  const ask = async (name: string, p: string, init: RequestInit = {}): Promise<Seed> => ({
    name,
    text: await (await gw.fetch(new Request(`http://sim${p}`, init), p)).text(),
  });
  try {
    const status = [await ask('status idle', '/rest/v1/status')];
    sim.startProgram();
    for (let i = 0; i < 30; i++) sim.advance();
    status.push(await ask('status running', '/rest/v1/status'));
    status.push(await ask('status imperial', '/rest/v1/status?units=imperial'));
    sim.fault();
    status.push(await ask('status fault', '/rest/v1/status'));
    const fields = encodeURIComponent('axes.*,io.*');
    const monitor = await ask('monitor all', `/rest/v1/monitor?fields=${fields}`);
    return {
      status,
      info: [await ask('machine-info', '/rest/v1/machine-info')],
      monitor: [monitor, ioAsList(monitor), await ask('monitor', '/rest/v1/monitor')],
      stats: [
        await ask('stats', '/rest/v1/stats'),
        await ask('stats condensed', '/rest/v1/stats?condensed=true'),
      ],
      programs: [await ask('programs', '/rest/v1/programs?offset=0&limit=5')],
      unloader: [
        await ask('unloader', '/rest/v1/unloader'),
        await ask('unloader history', '/rest/v1/unloader?history=true'),
      ],
      login: [
        await ask('login', LOGIN_PATH, {
          method: 'POST',
          body: new URLSearchParams({ username: 'operator', password: 'operator' }),
          headers: { 'Content-Type': 'application/x-www-form-urlencoded' },
        }),
        await ask('login state', LOGIN_PATH),
      ],
    };
  } finally {
    sim.dispose();
  }
}

/** The manual's other I/O form: `"io": [{ "din": [...] }, { "dout": [...] }]` (wire.ts ioSchema). */
function ioAsList(s: Seed): Seed {
  const o = JSON.parse(s.text) as { io?: Record<string, unknown> };
  const io = Object.entries(o.io ?? {}).map(([k, v]) => ({ [k]: v }));
  return { name: `${s.name} (io as a list of groups)`, text: JSON.stringify({ ...o, io }) };
}

let seeds: Seeds;
let all: Seed[] = [];
const { server } = fuzzHarness(async () => {
  seeds = await simSeeds();
  all = [...Object.values(seeds).flat(), ...MANUAL, ...CAPTURED];
});

function jsonOf(text: string): unknown {
  try {
    return JSON.parse(text);
  } catch {
    return null;
  }
}

function checkProto(what: string, value: unknown, m: Mutant, findings: Findings): void {
  const f = foreignPrototype(value);
  if (f) findings.add('prototype', `${what}: a __proto__ key became the prototype of ${f}`, m);
}

describe('TouchCut: hostile payloads through the parsers', () => {
  it('has seeds for every read (the simulator answered them)', () => {
    for (const [k, list] of Object.entries(seeds)) {
      expect(list.length, k).toBeGreaterThan(0);
      for (const s of list) expect(jsonOf(s.text), `${k}: ${s.name}`).not.toBeNull();
    }
    expect(wire.statusSchema.safeParse(jsonOf(seeds.status[1]?.text ?? '')).success).toBe(true);
    expect(
      wire.statsSchema.safeParse(jsonOf(seeds.stats[0]?.text ?? '')).data?.sessions.length,
    ).toBeGreaterThan(0);
    expect(wire.heldLoginSchema.safeParse(jsonOf(seeds.login[0]?.text ?? '')).data?.loggedIn).toBe(true);
  });

  it('every wire schema, and what reads its output: no exception, no prototype from a payload', () => {
    const mut = new Mutator(SEED, { depths: [20, 200, 1000], veryDeep: 0 });
    const findings = new Findings();
    const targets: Array<{ name: string; schema: z.ZodMiniType; seeds: () => Seed[] }> = [
      { name: 'status', schema: wire.statusSchema, seeds: () => seeds.status },
      { name: 'machine-info', schema: wire.machineInfoSchema, seeds: () => seeds.info },
      { name: 'monitor', schema: wire.monitorSchema, seeds: () => seeds.monitor },
      { name: 'stats', schema: wire.statsSchema, seeds: () => seeds.stats },
      { name: 'programs', schema: wire.openDataSchema, seeds: () => seeds.programs },
      { name: 'unloader', schema: wire.openDataSchema, seeds: () => seeds.unloader },
      { name: 'held login', schema: wire.heldLoginSchema, seeds: () => seeds.login },
      { name: 'auth', schema: wire.authResponseSchema, seeds: () => MANUAL },
      { name: 'error body', schema: wire.errorBodySchema, seeds: () => MANUAL },
    ];
    let clock: JobClock = { name: null, startedAt: null, lastProgress: null };
    let snap = emptySnapshot('fuzz');
    let programs: unknown = jsonOf(seeds.programs[0]?.text ?? '{}');
    for (let i = 0; i < 4000; i++) {
      const t = mut.rand.pick(targets);
      const m = mut.mutate(mut.rand.chance(0.9) ? mut.rand.pick(t.seeds()) : mut.rand.pick(all));
      const r = parseChecked(t.name, t.schema, m, findings);
      const body = jsonOf(m.text);
      guarded('parseTouchcutError', m, findings, () =>
        parseTouchcutError(mut.rand.pick([200, 401, 403, 500]), body, m.text),
      );
      if (!r?.success) continue;
      const data: unknown = r.data;
      switch (t.name) {
        case 'status': {
          const s = data as wire.Status;
          const out = guarded('snapshotPatch', m, findings, () => snapshotPatch(s, snap, clock, Date.now()));
          if (out) {
            clock = out.clock;
            snap = { ...snap, ...out.patch };
            const p = snapshotProblem(snap);
            if (p) findings.add('snapshot', p, m);
          }
          const w = guarded('readTouchcutStatus', m, findings, () => readTouchcutStatus(200, m.text));
          checkProto('readTouchcutStatus', w, m, findings);
          break;
        }
        case 'machine-info':
          guarded('identityOf', m, findings, () => identityOf(data as wire.MachineInfoWire));
          break;
        case 'stats': {
          const s = data as wire.Stats;
          guarded('stats views', m, findings, () => {
            sessionsByUser(s.sessions);
            toolTotalsOfSessions(s.sessions);
            totalsRows(s.machine);
            totalsRows(s.machineResettable);
            consumableTotals(s.consumables);
            programCounts(s.programs);
          });
          break;
        }
        case 'programs': {
          const merged = guarded('mergeChanged', m, findings, () => mergeChanged(programs, data));
          checkProto('mergeChanged', merged, m, findings);
          if (merged !== undefined && mut.rand.chance(0.5)) programs = merged;
          break;
        }
        case 'held login':
          guarded('authFromHeld', m, findings, () => authFromHeld(data as wire.HeldLoginWire));
          break;
      }
    }
    // The gateway's login hooks read TouchCut's and the browser's bodies.
    for (let i = 0; i < 1500; i++) {
      const m = mut.mutate(mut.rand.pick([...MANUAL, ...seeds.login]));
      guarded('tokenOf', m, findings, () => tokenOf(m.text));
      const rest = guarded('withoutToken', m, findings, () => withoutToken(m.text));
      if (rest !== undefined) {
        const o = jsonOf(rest);
        checkProto('withoutToken', o, m, findings);
        if (typeof o === 'object' && o !== null && /"(token|jwt)"\s*:/i.test(rest))
          findings.add('secret', 'withoutToken kept a token field', m);
      }
      guarded('credentialsOf', m, findings, () =>
        credentialsOf(m.text, mut.rand.pick(['application/json', 'application/x-www-form-urlencoded', ''])),
      );
      guarded('jwtExpiry', m, findings, () => jwtExpiry(m.text));
      guarded('jwtExpiry', m, findings, () =>
        jwtExpiry(`x.${Buffer.from(m.text.slice(0, 2000)).toString('base64url')}.y`),
      );
      guarded('readTouchcutStatus', m, findings, () =>
        readTouchcutStatus(mut.rand.pick([200, 401, 500]), m.text),
      );
    }
    // Paths and queries the watch and sharing read (a browser's, not the controller's; cheap to try).
    for (let i = 0; i < 500; i++) {
      const p = `/rest/v1/${mut.rand.pick(['status', 'monitor', 'programs', 'stats', 'auth'])}${mut.rand.pick(['', '/', '//'])}`;
      const q = new URLSearchParams([
        [mut.rand.pick(['units', 'fields', '__proto__', 'constructor']), mut.rand.pick(MARKUP).slice(0, 50)],
      ]);
      guarded('touchcutShareRead', { text: `${p}?${q.toString()}`, how: 'path' }, findings, () =>
        touchcutShareRead(p, q),
      );
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('data nested deeper than the stack: refused or merged, never thrown', () => {
    const findings = new Findings();
    for (const kind of ['object', 'array'] as const) {
      const deep = deepText(VERY_DEEP, kind, 'null', 'a');
      for (const [name, schema] of [
        ['status', wire.statusSchema],
        ['monitor', wire.monitorSchema],
        ['stats', wire.statsSchema],
        ['programs', wire.openDataSchema],
      ] as const) {
        const m: Mutant = {
          text: `{"msgStatus":${deep},"io":${deep},"axes":${deep},"x":${deep},"sessions":${deep}}`,
          how: `${name}: every field nested ${VERY_DEEP} deep (${kind})`,
        };
        parseChecked(name, schema, m, findings);
      }
      // Changed programs data merged into a page as deep as the answer: the merge must not recurse past the stack.
      const m: Mutant = {
        text: `{"a":${deep}}`,
        how: `programs page and its change nested ${VERY_DEEP} deep (${kind})`,
      };
      const base = jsonOf(m.text);
      const changed = jsonOf(m.text);
      const merged = guarded('mergeChanged', m, findings, () => mergeChanged(base, changed));
      if (merged === undefined || merged === null) findings.add('merge', 'mergeChanged lost the page', m);
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('I/O groups named like Object members are unknown groups, not inherited functions', () => {
    const findings = new Findings();
    for (const k of ['constructor', 'toString', 'hasOwnProperty', 'valueOf', '__proto__']) {
      const m: Mutant = {
        text: `{"io":[{"${k}":[{"name":"x"}]},{"${k}":1},{"din":[{"name":"in 1","value":"1"}]}],"axes":[{"io":[{"${k}":2}]}]}`,
        how: `io group ${k}`,
      };
      const r = parseChecked('monitor', wire.monitorSchema, m, findings);
      if (!r?.success) findings.add('refused', `monitor: io group ${k} refused`, m);
      else expect(r.data.io.din).toEqual([{ name: 'in 1', value: true }]);
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('a changed-data answer cannot replace the merged page prototype', () => {
    const findings = new Findings();
    const m: Mutant = {
      text: '{"programs":[],"__proto__":{"polluted":"fuzz"},"constructor":{"prototype":{"isAdmin":true}}}',
      how: 'prototype keys in changed data',
    };
    const merged = mergeChanged({ programs: [1], units: 'metric' }, jsonOf(m.text));
    checkProto('mergeChanged', merged, m, findings);
    expect(findings.count, report(findings)).toBe(0);
    expect(Object.getPrototypeOf(merged)).toBe(Object.prototype);
    expect(merged).toMatchObject({ programs: [], units: 'metric' });
    // The key stays data (own, as JSON.parse made it): shown as sent, never inherited.
    expect(Object.hasOwn(merged as object, '__proto__')).toBe(true);
  });
});

describe('TouchCut: hostile payloads through a running session', () => {
  it('status, monitor, machine-info, screen, login state, programs and stats: alive, nothing escapes, the snapshot stays sane', async () => {
    vi.useFakeTimers({ toFake: [...FAKE_TIMERS.toFake] });
    const id = 'fuzz-touchcut';
    const inner = new TouchcutSimulator({ id, name: 'Fuzzed TouchCut', tickMs: 250 });
    inner.autoOperator = false;
    const sim = new FuzzSimulator(viaGateway(inner, SIM_MONITOR_API_KEY));
    server.use(...simulatorHandlers(id, sim));
    const ctx = createContext(
      { id, name: 'Fuzzed TouchCut', kind: 'touchcut', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const session = new TouchcutSession(ctx);
    const findings = new Findings();
    let current: Mutant | string = 'connecting';
    const unwatch = watchBoundary(session.tracker, ctx.log, findings, () => current);
    const uncaught = captureUncaught(findings, () => current);
    const step = async (ms = 50) => {
      await vi.advanceTimersByTimeAsync(ms);
    };
    const releaseMonitor = session.monitor.acquire();
    session.monitor.setFields(['axes.*', 'io.*']);
    const unsubscribeScreen = session.screenshot.subscribe();
    try {
      session.start();
      for (let t = 0; t < 100 && ctx.snapshot.getState().link !== 'online'; t++) await step();
      expect(ctx.snapshot.getState().link).toBe('online');
      inner.startProgram();
      const mut = new Mutator(SEED + 2, { depths: [20, 200, 1000], veryDeep: 0 });
      const starts = (p: string) => (_m: string, path: string) => path.split('?')[0] === p;
      const targets = [
        { match: starts('/rest/v1/status'), seeds: () => seeds.status, weight: 6 },
        { match: starts('/rest/v1/monitor'), seeds: () => seeds.monitor, weight: 2 },
        { match: starts('/rest/v1/screenshot'), seeds: () => all, weight: 1 },
      ];
      const weighted = targets.flatMap((t) => Array.from({ length: t.weight }, () => t));
      const seen = new Set<string>();
      const check = (m: Mutant) => {
        const p = snapshotProblem(ctx.snapshot.getState());
        if (p) findings.add('snapshot', p, m);
        checkProto('monitor data', session.monitor.store.getState().data, m, findings);
        // The feeds show their own errors: an exception's words there went past the parser.
        for (const [feed, error] of [
          ['monitor', session.monitor.store.getState().error],
          ['screen', session.screenshot.store.getState().error],
        ] as const)
          if (error && EXCEPTION_WORDS.test(error)) findings.add('exception', `${feed} shows: ${error}`, m);
        checkProto('store', session.store.getState(), m, findings);
        if (!session.started) findings.add('session', 'the session stopped', m);
        seen.add(ctx.snapshot.getState().link);
      };
      for (let i = 0; i < 300; i++) {
        const t = mut.rand.pick(weighted);
        const m = mut.mutate(mut.rand.pick(t.seeds()));
        current = m;
        const status = mut.rand.chance(0.1) ? mut.rand.pick([400, 403, 500]) : 200;
        sim.answerNext(t.match, m, status);
        const served = sim.served;
        for (let k = 0; k < 100 && sim.served === served; k++) await step(50);
        await step(10);
        check(m);
      }
      expect(sim.served).toBeGreaterThan(250);

      // Machine-info (read until known), and the gateway's login state (another viewer's login).
      for (let i = 0; i < 40; i++) {
        const info = i % 2 === 0;
        const m = mut.mutate(mut.rand.pick(info ? seeds.info : seeds.login));
        current = m;
        if (info) session.store.setState({ info: null });
        sim.answerNext(starts(info ? '/rest/v1/machine-info' : LOGIN_PATH), m);
        const served = sim.served;
        if (info) {
          // A status failure and recovery kicks machine-info while it is unknown.
          sim.answerNext(starts('/rest/v1/status'), { text: '', how: 'empty status' }, 500);
          for (let k = 0; k < 60 && sim.served === served; k++) await step(50);
          sim.answerNext(starts('/rest/v1/machine-info'), m);
        } else session.retryWithoutLogin();
        for (let k = 0; k < 400 && sim.served <= served; k++) await step(50);
        await step(20);
        check(m);
      }

      // On-demand reads: programs (a refresh merges changed data into the page) and stats.
      const page = { offset: 0, limit: 25, history: null };
      const req = { startDate: '2025-01-01', endBeforeDate: '2025-01-08', condensed: false };
      for (let i = 0; i < 120; i++) {
        const programs = i % 2 === 0;
        const m = mut.mutate(mut.rand.pick(programs ? seeds.programs : seeds.stats));
        current = m;
        sim.answerNext(starts(programs ? '/rest/v1/programs' : '/rest/v1/stats'), m);
        const fetcher = programs
          ? session.programs.read(page, 'default')
          : session.stats.read(req, 'default');
        const out = await Promise.allSettled([fetcher(new AbortController().signal)]);
        const r = out[0];
        if (r?.status === 'fulfilled') checkProto(programs ? 'programs' : 'stats', r.value, m, findings);
        else if (r && !(r.reason instanceof Error && r.reason.name === 'LinkError'))
          findings.add('exception', `${programs ? 'programs' : 'stats'} read threw ${String(r.reason)}`, m);
        check(m);
      }

      expect(seen).toContain('protocol-error');
      expect(seen).toContain('online');
      expect(session.started).toBe(true);
      // After the storm, the simulator's own answers bring the machine back.
      current = 'recovery';
      for (let t = 0; t < 100 && ctx.snapshot.getState().link !== 'online'; t++) await step(100);
      expect(ctx.snapshot.getState().link).toBe('online');
    } finally {
      releaseMonitor();
      unsubscribeScreen();
      uncaught();
      unwatch();
      session.stop();
      sim.dispose();
    }
    expect(findings.count, report(findings)).toBe(0);
  }, 90_000);
});
