import { describe, expect, it, vi } from 'vitest';
import type { z } from 'zod/mini';
import {
  FAKE_TIMERS,
  Findings,
  FuzzSimulator,
  Mutator,
  VERY_DEEP,
  captureUncaught,
  deepText,
  fixtureFiles,
  foreignPrototype,
  guarded,
  jsonLines,
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
import { parseG2Error } from './client';
import {
  activityLabelOf,
  alarmsOf,
  describeStatus,
  identityOf,
  initialDetail,
  jobSummary,
  machineInfoOf,
  num,
  positionsOf,
  type TrackedOp,
} from './model';
import { G2coreSession } from './session';
import { readStatusReport } from './sharing';
import { G2coreSimulator } from './sim/simulator';
import * as wire from './wire';

// Pure CPU work: on a loaded 2-core machine a case takes 20–35 s; the time bound is not the test.
vi.setConfig({ testTimeout: 90_000 });

/**
 * Hostile input for the g2core family (issue 15): thousands of payloads mutated from the captures
 * and REST design examples in tests/fixtures/g2core and from the simulator's answers, through
 * every wire schema, the error parser, the model mapping and the gateway's watch reader, and as
 * answers to a running session's polls (status reports, the job list, tracked operations, the
 * version and axes read on reconnect). Nothing may throw past the boundary, no `__proto__` key may
 * become a prototype, and the session stays alive. Seeded: a failure names its payload and replays.
 */

const SEED = 0x15_0003;

/** Fixture answers: whole JSON files, JSON-lines replies, and what the captured sessions received. */
function fixtureSeeds(): Seed[] {
  const out: Seed[] = [];
  for (const f of fixtureFiles('g2core/rest-design-examples')) out.push(f);
  for (const f of fixtureFiles('g2core/responses', ['.json', '.jsonl'])) {
    if (f.name.endsWith('.jsonl'))
      jsonLines(f.text).forEach((l, i) => out.push({ name: `${f.name}#${i}`, text: l }));
    else out.push(f);
  }
  for (const f of fixtureFiles('g2core/sessions', ['.jsonl'])) {
    jsonLines(f.text).forEach((l, i) => {
      const line = JSON.parse(l) as { dir?: string; raw?: string };
      if (line.dir === 'rx' && typeof line.raw === 'string')
        out.push({ name: `${f.name}#${i}`, text: line.raw });
    });
  }
  return out;
}

interface SimSeeds {
  version: Seed[];
  status: Seed[];
  tree: Seed[];
  shallow: Seed[];
  value: Seed[];
  created: Seed[];
  op: Seed[];
  ops: Seed[];
  job: Seed[];
  jobs: Seed[];
  errors: Seed[];
}

/** The simulator's answers to what the console asks, with a job and operations under way. */
async function simSeeds(): Promise<SimSeeds> {
  const sim = new G2coreSimulator({ id: 'seed', name: 'Seed g2core' });
  try {
    const ask = async (p: string, init: RequestInit = {}): Promise<Seed> => {
      const res = await sim.fetch(new Request(`http://sim${p}`, init), p);
      return { name: `${init.method ?? 'GET'} ${p}`, text: await res.text() };
    };
    const post = (p: string, body: unknown) => ask(p, { method: 'POST', body: JSON.stringify(body) });
    const job = await post('/job', { name: 'part.nc', gcode: 'G21\nG90\nG1 X10 F600\nG1 X20\nG1 X30' });
    const jobId = String(JSON.parse(job.text));
    await post('/operation', { optype: 'sendfile', value: jobId });
    const op = await post('/operation', { optype: 'run', value: ['G4 P1', '{"xvm":null}'] });
    const opId = String(JSON.parse(op.text));
    const q = (filter: unknown) => `?filter=${encodeURIComponent(JSON.stringify(filter))}`;
    return {
      version: [await ask('/version')],
      status: [await ask('/status_report'), await ask(`/status_report${q({ posx: 0, stat: 1 })}`)],
      tree: [
        await ask(`/machine${q({ x: { am: null }, y: { am: null }, mfoe: null, ssoe: null })}`),
        await ask('/machine'),
      ],
      shallow: [await ask('/machine?shallow=true')],
      value: [await ask('/machine/x/vm'), await ask('/machine/ct'), await ask('/machine/g54')],
      created: [job, op],
      op: [await ask(`/operation/${opId}`)],
      ops: [await ask('/operation')],
      job: [await ask(`/job/${jobId}`)],
      jobs: [await ask('/job')],
      errors: [
        await ask('/machine/nope'),
        await ask('/operation/999999'),
        await post('/operation', { optype: 'run', value: 'G1 X10' }),
      ],
    };
  } finally {
    sim.dispose();
  }
}

const FIXTURES = fixtureSeeds();
let seeds: SimSeeds;
const { server } = fuzzHarness(async () => {
  seeds = await simSeeds();
});

function json(text: string): unknown {
  try {
    return JSON.parse(text) as unknown;
  } catch {
    return null;
  }
}

const byName = (re: RegExp) => FIXTURES.filter((f) => re.test(f.name));

describe('g2core: hostile payloads through the parsers', () => {
  function targets(): Array<{ name: string; schema: z.ZodMiniType; seeds: Seed[] }> {
    return [
      {
        name: 'version',
        schema: wire.versionResponse,
        seeds: [...seeds.version, ...byName(/version|startup/)],
      },
      {
        name: 'status report',
        schema: wire.statusReportResponse,
        seeds: [...seeds.status, ...byName(/status_report|sessions/)],
      },
      {
        name: 'machine tree',
        schema: wire.machineTreeResponse,
        seeds: [...seeds.tree, ...byName(/GET-machine\.|config-groups/)],
      },
      { name: 'shallow', schema: wire.shallowResponse, seeds: seeds.shallow },
      {
        name: 'machine value',
        schema: wire.machineValueResponse,
        seeds: [...seeds.value, ...byName(/ct|x-axis|sys-group/)],
      },
      { name: 'created id', schema: wire.createdId, seeds: [...seeds.created, ...byName(/POST-operation/)] },
      { name: 'operation', schema: wire.operationResponse, seeds: seeds.op },
      { name: 'operation list', schema: wire.operationListResponse, seeds: seeds.ops },
      { name: 'job', schema: wire.jobResponse, seeds: seeds.job },
      { name: 'job list', schema: wire.jobListResponse, seeds: seeds.jobs },
      { name: 'error body', schema: wire.errorBody, seeds: [...seeds.errors, ...byName(/error|exception/)] },
      { name: 'exception report', schema: wire.exceptionReport, seeds: byName(/exception|feedhold/) },
    ];
  }

  it('has seeds for every schema', () => {
    for (const t of targets()) expect(t.seeds.length, t.name).toBeGreaterThan(0);
    expect(FIXTURES.length).toBeGreaterThan(30);
  });

  it('every wire schema, the error parser and the watch reader: no exception, no prototype from a payload', () => {
    const ts = targets();
    const all = ts.flatMap((t) => t.seeds);
    const mut = new Mutator(SEED);
    const findings = new Findings();
    let n = 0;
    for (let i = 0; i < 3000; i++) {
      const t = mut.rand.pick(ts);
      const m = mut.mutate(mut.rand.chance(0.9) ? mut.rand.pick(t.seeds) : mut.rand.pick(all));
      parseChecked(t.name, t.schema, m, findings);
      const status = mut.rand.pick([200, 201, 400, 404, 405, 410, 500, 502]);
      const err = guarded('parseG2Error', m, findings, () => parseG2Error(status, json(m.text), m.text));
      if (err) {
        const f = foreignPrototype(err);
        if (f) findings.add('prototype', `parseG2Error: ${f}`, m);
        if (typeof err.message !== 'string' || err.message.length > 2000)
          findings.add('words', `parseG2Error: a message of ${err.message.length} characters`, m);
      }
      const watch = guarded('readStatusReport', m, findings, () => readStatusReport(status, m.text));
      if (watch && !(watch instanceof Error)) {
        const f = foreignPrototype(watch);
        if (f) findings.add('prototype', `readStatusReport: ${f}`, m);
      }
      guarded('valueForKey', m, findings, () =>
        wire.valueForKey(json(m.text), mut.rand.chance(0.5) ? 'x' : null, 'vm'),
      );
      n++;
    }
    expect(n).toBe(3000);
    expect(findings.count, report(findings)).toBe(0);
  });

  it('parsed answers through the model (snapshot words, DRO, jobs, identity): no exception, numbers stay finite', () => {
    const mut = new Mutator(SEED + 1);
    const findings = new Findings();
    for (let i = 0; i < 2500; i++) {
      const kind = mut.rand.int(4);
      if (kind === 0) {
        const m = mut.mutate(mut.rand.pick([...seeds.status, ...byName(/status_report/)]));
        const p = parseChecked('status report', wire.statusReportResponse, m, findings);
        if (!p?.success) continue;
        const sr = p.data;
        const d = { ...initialDetail(), sr };
        const pos = guarded('positionsOf', m, findings, () => positionsOf(d)) ?? {};
        for (const [k, v] of Object.entries(pos))
          if (!Number.isFinite(v)) findings.add('model', `position ${k} = ${v}`, m);
        guarded('alarmsOf', m, findings, () => alarmsOf(num(sr.stat), 0, null));
        guarded('activityLabelOf', m, findings, () => activityLabelOf(num(sr.stat), []));
      } else if (kind === 1) {
        const m = mut.mutate(mut.rand.pick([...seeds.tree, ...byName(/GET-machine\.|config-groups/)]));
        const p = parseChecked('machine tree', wire.machineTreeResponse, m, findings);
        if (p?.success) guarded('machineInfoOf', m, findings, () => machineInfoOf(p.data.value));
        const raw = json(m.text);
        if (typeof raw === 'object' && raw !== null)
          guarded('machineInfoOf (raw)', m, findings, () => machineInfoOf(raw as Record<string, unknown>));
      } else if (kind === 2) {
        const m = mut.mutate(mut.rand.pick(seeds.jobs));
        const p = parseChecked('job list', wire.jobListResponse, m, findings);
        if (!p?.success) continue;
        const jobs = p.data;
        const s = guarded('jobSummary', m, findings, () => jobSummary(jobs, Date.now()));
        if (s) {
          if (s.progress !== null && !(Number.isFinite(s.progress) && s.progress >= 0 && s.progress <= 1))
            findings.add('model', `job progress ${s.progress}`, m);
          for (const v of [s.elapsed, s.remaining])
            if (v !== null && !Number.isFinite(v)) findings.add('model', `job time ${v}`, m);
        }
        for (const j of jobs)
          if (j.error) guarded('describeStatus', m, findings, () => describeStatus(j.error ?? { code: 0 }));
        guarded('activityLabelOf', m, findings, () => activityLabelOf(5, jobs));
      } else {
        const m = mut.mutate(mut.rand.pick([...seeds.version, ...byName(/version|startup/)]));
        const p = parseChecked('version', wire.versionResponse, m, findings);
        if (p?.success) guarded('identityOf', m, findings, () => identityOf(p.data));
      }
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('answers nested beyond the stack are refused or read, never thrown', () => {
    const findings = new Findings();
    for (const kind of ['object', 'array'] as const) {
      const deep = deepText(VERY_DEEP, kind);
      const bodies = [
        `{"posx":${deep}}`,
        `{"value":${deep}}`,
        `{"opstate":"done","r":[{"a":${deep}}]}`,
        `[{"id":"1","state":"done","error":${deep}}]`,
        `{"status":{"code":100,"description":${deep}}}`,
      ];
      for (const text of bodies) {
        const m: Mutant = { text, how: `nested ${VERY_DEEP} deep (${kind})` };
        for (const [name, schema] of [
          ['status report', wire.statusReportResponse],
          ['machine value', wire.machineValueResponse],
          ['operation', wire.operationResponse],
          ['job list', wire.jobListResponse],
          ['error body', wire.errorBody],
        ] as const)
          parseChecked(name, schema, m, findings);
        guarded('parseG2Error', m, findings, () => parseG2Error(404, json(text), text));
        guarded('readStatusReport', m, findings, () => readStatusReport(200, text));
      }
    }
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe('g2core: hostile answers through a running session', () => {
  it('status reports, jobs, operations, version and axes: the session stays alive, nothing escapes', async () => {
    vi.useFakeTimers({ toFake: [...FAKE_TIMERS.toFake] });
    const id = 'fuzz-g2core';
    const sim = new FuzzSimulator(new G2coreSimulator({ id, name: 'Fuzzed g2core' }));
    server.use(...simulatorHandlers(id, sim));
    const ctx = createContext(
      { id, name: 'Fuzzed g2core', kind: 'g2core', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const session = new G2coreSession(ctx);
    const findings = new Findings();
    let current: Mutant | string = 'connecting';
    const unwatch = watchBoundary(session.tracker, ctx.log, findings, () => current);
    const uncaught = captureUncaught(findings, () => current);
    const step = async (ms = 50) => {
      await vi.advanceTimersByTimeAsync(ms);
    };
    const check = (m: Mutant) => {
      const p = snapshotProblem(ctx.snapshot.getState());
      if (p) findings.add('snapshot', p, m);
      const f = foreignPrototype(session.detail.getState());
      if (f) findings.add('prototype', `a __proto__ key became the prototype of detail ${f}`, m);
      if (!session.started) findings.add('session', 'the session stopped', m);
    };
    try {
      session.start();
      for (let t = 0; t < 100 && ctx.snapshot.getState().link !== 'online'; t++) await step();
      expect(ctx.snapshot.getState().link).toBe('online');
      const mut = new Mutator(SEED + 2, { depths: [20, 200, 1000], veryDeep: 0.05 });
      const seen = new Set<string>();
      let opSeq = 0;
      const get = (path: RegExp) => (method: string, p: string) =>
        method === 'GET' && path.test(p.split('?')[0] ?? p);
      const kinds = [
        { match: get(/^\/status_report$/), seeds: () => [...seeds.status, ...byName(/status_report/)] },
        { match: get(/^\/job$/), seeds: () => seeds.jobs },
        { match: get(/^\/version$/), seeds: () => [...seeds.version, ...byName(/version|startup/)] },
        { match: get(/^\/machine$/), seeds: () => seeds.tree },
        { match: get(/^\/operation\/fz-/), seeds: () => seeds.op },
      ];
      const track = (): string => {
        // An MDI operation this console tracks: its state comes from GET /operation/{id}.
        const opId = `fz-${++opSeq}`;
        const t: TrackedOp = {
          id: opId,
          purpose: 'mdi',
          label: `MDI ${opId}`,
          lines: ['{"xvm":null}'],
          op: null,
          startedAt: Date.now(),
        };
        session.detail.setState((d) => ({
          ops: { ...d.ops, [opId]: t },
          console: [
            ...d.console.slice(-20),
            { seq: opSeq, at: Date.now(), lines: t.lines, opId, state: 'sent', message: null },
          ],
        }));
        return opId;
      };
      const online = async () => {
        for (let w = 0; w < 120 && ctx.snapshot.getState().link !== 'online'; w++) await step(50);
      };
      const serve = async (match: (method: string, p: string) => boolean, m: Mutant, status = 200) => {
        const served = sim.served;
        sim.answerNext(match, m, status);
        for (let w = 0; w < 120 && sim.served === served; w++) await step(50);
        await step(100);
        check(m);
      };

      // Directed: replies nested beyond the stack, text values and keys no URL holds, prototype keys.
      const deepOp = track();
      const deepReply: Mutant = {
        text: `{"opstate":"done","optype":"run","r":[{"xvm":${deepText(VERY_DEEP, 'object')}}]}`,
        how: `an operation's reply nested ${VERY_DEEP} deep`,
      };
      current = deepReply;
      await serve(get(/^\/operation\/fz-/), deepReply);
      expect(session.detail.getState().ops[deepOp]?.op?.opstate.state).toBe('done');
      /** The path of the next status read (after `m`, once applied): its changed-only filter. */
      const nextAsk = async (): Promise<string> => {
        let asked = '';
        const inner = sim.inner.fetch.bind(sim.inner);
        sim.inner.fetch = (req, p) => {
          if (p.startsWith('/status_report')) asked = p;
          return inner(req, p);
        };
        for (let w = 0; w < 40 && asked === ''; w++) await step(50);
        sim.inner.fetch = inner;
        return asked;
      };
      // Values no URL holds are not sent back as the changed-only filter.
      const huge: Mutant = {
        text: JSON.stringify({ stat: 3, posx: 1, junk: 'A'.repeat(100_000) }),
        how: 'a 100 kB value',
      };
      const wide: Mutant = {
        text: JSON.stringify(Object.fromEntries(Array.from({ length: 3000 }, (_, i) => [`k${i}`, i]))),
        how: '3000 keys',
      };
      for (const m of [huge, wide]) {
        current = m;
        await serve(get(/^\/status_report$/), m);
        expect(ctx.snapshot.getState().link).toBe('online');
        const asked = await nextAsk();
        expect(asked).not.toBe('');
        expect(asked.length, m.how).toBeLessThan(8000);
      }
      const proto: Mutant = {
        text: '{"stat":3,"__proto__":{"polluted":"fuzz","stat":4},"constructor":{"prototype":{"polluted":"fuzz"}}}',
        how: 'prototype keys in a status report',
      };
      current = proto;
      await serve(get(/^\/status_report$/), proto);
      // Refused as a protocol error (an object where a value goes); back once a good report comes.
      expect(ctx.snapshot.getState().link).toBe('protocol-error');
      await online();
      expect(ctx.snapshot.getState().link).toBe('online');

      let mdiSettled = 0;
      for (let i = 0; i < 200; i++) {
        const k = mut.rand.pick(kinds);
        const m = mut.mutate(mut.rand.pick(k.seeds()));
        current = m;
        let opId: string | null = null;
        if (k === kinds[4]) opId = track();
        if (k === kinds[2] || k === kinds[3]) {
          // Version and axes are read on (re)connect only: a cut status answer brings them.
          await online();
          sim.answerNext(get(/^\/status_report$/), { text: '{"posx":1', how: 'a cut answer' });
          for (let w = 0; w < 100 && sim.waiting; w++) await step(50);
        } else if (k !== kinds[0]) await online(); // the slow poll runs while online
        const served = sim.served;
        sim.answerNext(k.match, m, mut.rand.chance(0.1) ? mut.rand.pick([400, 404, 500]) : 200);
        for (let w = 0; w < 120 && sim.served === served; w++) await step(50);
        await step(mut.rand.pick([20, 100, 300]));
        check(m);
        seen.add(ctx.snapshot.getState().link);
        if (opId && session.detail.getState().ops[opId]?.op) mdiSettled++;
      }
      // The operation answers reached the tracker (a test that cannot fail is worse than none).
      expect(mdiSettled).toBeGreaterThan(5);
      expect(sim.served).toBeGreaterThan(190);
      // Refused payloads showed as protocol errors, good ones brought the machine back.
      expect(seen).toContain('protocol-error');
      expect(seen).toContain('online');
      expect(session.started).toBe(true);
      current = 'recovery';
      for (let t = 0; t < 200 && ctx.snapshot.getState().link !== 'online'; t++) await step(50);
      expect(ctx.snapshot.getState().link).toBe('online');
    } finally {
      uncaught();
      unwatch();
      session.stop();
      sim.dispose();
    }
    expect(findings.count, report(findings)).toBe(0);
  }, 90_000);
});
