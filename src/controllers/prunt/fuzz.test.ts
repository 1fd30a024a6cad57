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
  describe as describeErr,
  type Mutant,
  type Seed,
  fuzzHarness,
  report,
} from '../../../tests/faults/fuzz';
import { LinkTracker } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { createContext } from '../../fleet/fleet';
import { createSharedStore } from '../../fleet/kernel';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { FormModel } from '../../forms/model';
import { memoryDraftStorage } from '../../forms/storage';
import { parsePruntError, PruntClient } from './client';
import { buildForm, placeErrors, readValues, type PruntForm } from './config-ir';
import { History } from './history';
import { PruntLive } from './live';
import { PruntSession } from './session';
import { classifyPruntFrame, readPruntFrame } from './sharing';
import { loadBoard3 } from './sim/board';
import { PruntSimulator } from './sim/sim';
import { initialPruntState, type PruntState } from './state';
import { activityOf, buildStatusModel, derive, normalizeFlat, type StatusModule } from './status';
import * as wire from './wire';

// Pure CPU work: on a loaded 2-core machine a case takes 20–35 s; the time bound is not the test.
vi.setConfig({ testTimeout: 90_000 });

/**
 * Hostile input for the Prunt family (issue 15): thousands of payloads mutated from the captures
 * in tests/fixtures/prunt (both API generations) and from the simulator's answers, through every
 * wire schema, the config-form builder, the status model, the client's own parsing, the live
 * frame handler, and a running session's `/websocket/everything` and reads. Nothing may throw past
 * the boundary, no `__proto__` key may become a prototype, the session stays alive, and an unsaved
 * config edit survives every bad payload. Seeded: a failure names its payload and replays.
 */

const SEED = 0x15_0005;
/** The edit the session test keeps unsaved (the matrix uses the same field). */
const FIELD = 'Steppers$Steppers$STEPPER_1$Run current';

const FILES = fixtureFiles('prunt');
const FRAMES: Seed[] = fixtureFiles('prunt', ['.jsonl']).flatMap((f) =>
  jsonLines(f.text).map((text, i) => ({ name: `${f.name}#${i}`, text })),
);

function seedsOf(match: RegExp): Seed[] {
  return FILES.filter((f) => match.test(f.name));
}

/** The simulator's answers to the reads the session makes, for both generations. */
async function simSeeds(): Promise<Record<string, Seed[]>> {
  const out: Record<string, Seed[]> = {};
  for (const api of ['module', 'flat'] as const) {
    const sim = new PruntSimulator({ id: `seed-${api}`, name: 'Seed', api });
    try {
      for (const p of ['/config/schema', '/config/values', '/status/schema', '/status/values', '/uploads/']) {
        const res = await sim.fetch(new Request(`http://sim${p}`), p);
        (out[p] ??= []).push({ name: `sim ${api} ${p}`, text: await res.text() });
      }
      const up = api === 'module' ? '/update-check' : '/update_check';
      const res = await sim.fetch(new Request(`http://sim${up}`), up);
      (out['/update-check'] ??= []).push({ name: `sim ${api} ${up}`, text: await res.text() });
    } finally {
      sim.dispose();
    }
  }
  return out;
}

/** Ticks as the server frames them, from status values (module: `Status_Values`, flat: `Status`). */
function tickSeeds(values: Seed[]): Seed[] {
  return values.map((v) => {
    const parsed: unknown = JSON.parse(v.text);
    const isFlat = typeof parsed === 'object' && parsed !== null && 'Status' in parsed;
    return {
      name: `tick from ${v.name}`,
      text: isFlat
        ? v.text
        : `{"Status_Values":${v.text}, "Smart_Plug":null, "Server_Exception":null, "Startup": "Done"}`,
    };
  });
}

let sim: Record<string, Seed[]> = {};
let frames: Seed[] = [];
const { server } = fuzzHarness(async () => {
  await loadBoard3();
  sim = await simSeeds();
  frames = [...FRAMES, ...tickSeeds([...(sim['/status/values'] ?? []), ...seedsOf(/status-values/)])];
});

function seeds(path: string, match: RegExp): Seed[] {
  return [...(sim[path] ?? []), ...seedsOf(match)];
}

/** A prototype key that became a prototype anywhere in a built form (its nodes are in a Map). */
function formPrototype(pf: PruntForm): string | null {
  for (const [id, n] of pf.form.nodes) {
    const f = foreignPrototype(n);
    if (f) return `node ${id} ${f}`;
  }
  return foreignPrototype({
    roots: pf.form.roots,
    versions: pf.moduleVersions,
    paths: [...pf.wirePath.values()],
  });
}

function jsonOf(text: string): unknown {
  try {
    return JSON.parse(text);
  } catch {
    return text;
  }
}

describe('Prunt: hostile payloads through the parsers', () => {
  it('has seeds for every answer and the live frames', () => {
    for (const p of [
      '/config/schema',
      '/config/values',
      '/status/schema',
      '/status/values',
      '/uploads/',
      '/update-check',
    ])
      expect(sim[p]?.length ?? 0, p).toBe(2);
    expect(seedsOf(/config-schema/).length).toBeGreaterThan(0);
    expect(seedsOf(/config-post/).length).toBeGreaterThan(1);
    expect(FRAMES.length).toBeGreaterThan(10);
  });

  it('every wire schema and the vendor error parser: no exception, no prototype from a payload', () => {
    const mut = new Mutator(SEED);
    const findings = new Findings();
    const targets: Array<{ name: string; schema: z.ZodMiniType; seeds: Seed[] }> = [
      {
        name: 'config values',
        schema: wire.configValuesSchema,
        seeds: seeds('/config/values', /config-values|config-post/),
      },
      {
        name: 'module values',
        schema: wire.moduleValuesSchema,
        seeds: seeds('/config/values', /v2026\/config-values/),
      },
      {
        name: 'status schema',
        schema: wire.statusSchemaSchema,
        seeds: seeds('/status/schema', /status-schema/),
      },
      {
        name: 'status values',
        schema: wire.statusValuesSchema,
        seeds: seeds('/status/values', /status-values/),
      },
      { name: 'update check', schema: wire.updateCheckSchema, seeds: seeds('/update-check', /update-check/) },
      { name: 'uploads', schema: wire.uploadsSchema, seeds: seeds('/uploads/', /uploads-list/) },
      {
        name: 'run-command reply',
        schema: wire.runCommandReplySchema,
        seeds: [{ name: 'ID', text: '{"ID":"7"}' }],
      },
      { name: 'live frame', schema: wire.wsMessageSchema, seeds: frames },
    ];
    const all = [...FILES, ...frames];
    for (let i = 0; i < 2000; i++) {
      const t = mut.rand.pick(targets);
      const m = mut.mutate(mut.rand.chance(0.9) ? mut.rand.pick(t.seeds) : mut.rand.pick(all));
      parseChecked(t.name, t.schema, m, findings);
      guarded('parsePruntError', m, findings, () => parsePruntError(500, jsonOf(m.text), m.text));
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('config schemas → the form, values → the form, errors placed: no exception, no prototype', () => {
    const mut = new Mutator(SEED + 1, { depths: [20, 200, 1000] });
    const findings = new Findings();
    const schemas = seeds('/config/schema', /config-schema/);
    const values = seeds('/config/values', /config-values|config-post/);
    let parsedForms = 0;
    for (let i = 0; i < 150; i++) {
      const m = mut.mutate(mut.rand.pick(schemas));
      const r = parseChecked('config schema', wire.configSchemaSchema, m, findings);
      if (!r?.success) continue;
      const pf = guarded('buildForm', m, findings, () => buildForm(r.data, m.text));
      if (!pf) continue;
      parsedForms++;
      const f = formPrototype(pf);
      if (f) findings.add('prototype', `buildForm: a __proto__ key became the prototype of ${f}`, m);
      guarded('FormModel', m, findings, () => new FormModel(pf.form));
      // Values and errors of either generation against this form.
      for (let k = 0; k < 2; k++) {
        const vm = mut.mutate(mut.rand.pick(values));
        const v = parseChecked('config values', wire.configValuesSchema, vm, findings);
        if (!v?.success) continue;
        const out = guarded('readValues', vm, findings, () => readValues(pf, v.data.Values));
        const fo = out && foreignPrototype(out);
        if (fo) findings.add('prototype', `readValues: prototype of ${fo}`, vm);
        guarded('placeErrors', vm, findings, () => placeErrors(pf, v.data.Errors));
      }
    }
    // The mutations left most schemas usable (a test that cannot reach the builder proves nothing).
    expect(parsedForms).toBeGreaterThan(25);
    expect(findings.count, report(findings)).toBe(0);
  });

  it('status schemas → the status model, values → what the fleet shows: no exception, sane numbers', () => {
    const mut = new Mutator(SEED + 2);
    const findings = new Findings();
    const schemas = seeds('/status/schema', /status-schema/);
    const values = seeds('/status/values', /status-values/);
    let derived = 0;
    for (let i = 0; i < 800; i++) {
      const sm = mut.mutate(mut.rand.pick(schemas));
      const s = parseChecked('status schema', wire.statusSchemaSchema, sm, findings);
      const model: StatusModule[] | undefined = s?.success
        ? guarded('buildStatusModel', sm, findings, () => buildStatusModel(s.data))
        : undefined;
      // Real values against a mutated model, mutated values against a real one.
      const good = wire.statusSchemaSchema.safeParse(JSON.parse(mut.rand.pick(schemas).text));
      const models = [model, good.success ? buildStatusModel(good.data) : undefined];
      const vm = mut.mutate(mut.rand.pick(values));
      const v = parseChecked('status values', wire.statusValuesSchema, vm, findings);
      if (!v?.success) continue;
      const status = guarded('normalizeFlat', vm, findings, () =>
        v.data.api === 'flat' ? normalizeFlat(v.data.values) : v.data.values,
      );
      if (!status) continue;
      const fs = foreignPrototype(status);
      if (fs) findings.add('prototype', `status values: prototype of ${fs}`, vm);
      for (const md of models) {
        if (!md) continue;
        const d = guarded('derive', vm, findings, () => derive(md, status));
        if (!d) continue;
        derived++;
        for (const [k, x] of Object.entries(d.positions))
          if (!Number.isFinite(x)) findings.add('derive', `position ${k} = ${x}`, vm);
        for (const t of d.temperatures)
          if (!Number.isFinite(t.current)) findings.add('derive', `temperature ${t.name} = ${t.current}`, vm);
        const fd = foreignPrototype(d);
        if (fd) findings.add('prototype', `derive: prototype of ${fd}`, vm);
        guarded('activityOf', vm, findings, () => activityOf(d, null, null));
      }
    }
    expect(derived).toBeGreaterThan(300);
    expect(findings.count, report(findings)).toBe(0);
  });

  it('a payload nested deeper than the stack is refused as a protocol error, not thrown', () => {
    const findings = new Findings();
    const schemas: Array<[string, z.ZodMiniType]> = [
      ['config schema', wire.configSchemaSchema],
      ['config values', wire.configValuesSchema],
      ['status schema', wire.statusSchemaSchema],
      ['status values', wire.statusValuesSchema],
      ['live frame', wire.wsMessageSchema],
    ];
    for (const [name, schema] of schemas)
      for (const kind of ['object', 'array'] as const)
        for (const at of ['root', 'inside'] as const) {
          const deep = deepText(VERY_DEEP, kind, 'null', 'Children');
          const text =
            at === 'root'
              ? deep
              : `{"Config":{"M":{"Version":1,"Config":{"a":{"Kind":"Sequence","Children":${deep}}}}},"Status":${deep}}`;
          const m: Mutant = { text, how: `${name}: nested ${VERY_DEEP} deep (${kind}, ${at})` };
          const r = parseChecked(name, schema, m, findings);
          if (r?.success) findings.add('accepted', `${name}: a payload ${VERY_DEEP} deep was accepted`, m);
          else if (r && !r.error.issues.some((i) => /nested deeper than/.test(i.message)))
            findings.add('words', `${name}: refused without saying why`, m);
        }
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe('Prunt: hostile answers through the client', () => {
  it('every read of the client resolves or fails with a LinkError, never anything else', async () => {
    const id = 'fuzz-prunt-client';
    const fsim = new FuzzSimulator(new PruntSimulator({ id, name: 'Client', api: 'module' }));
    server.use(...simulatorHandlers(id, fsim));
    const client = new PruntClient(id);
    const mut = new Mutator(SEED + 3, { depths: [20, 200, 1000] });
    const findings = new Findings();
    type Read = { path: string; seeds: Seed[]; call: () => Promise<unknown> };
    const reads: Read[] = [
      {
        path: '/config/schema',
        seeds: seeds('/config/schema', /config-schema/),
        call: () => client.configSchema(),
      },
      {
        path: '/config/values',
        seeds: seeds('/config/values', /config-values|config-post/),
        call: () => client.configValues(),
      },
      {
        path: '/status/schema',
        seeds: seeds('/status/schema', /status-schema/),
        call: () => client.statusSchema(),
      },
      {
        path: '/status/values',
        seeds: seeds('/status/values', /status-values/),
        call: () => client.statusValues(),
      },
      {
        path: '/update-check',
        seeds: seeds('/update-check', /update-check/),
        call: () => client.updateCheck('module'),
      },
      { path: '/uploads/', seeds: seeds('/uploads/', /uploads-list/), call: () => client.uploads() },
      {
        path: '/run-command',
        seeds: [{ name: 'ID', text: '{"ID":"7"}' }],
        call: () => client.runCommand('G28', { commandId: 'fuzz' }),
      },
    ];
    let refused = 0;
    let accepted = 0;
    try {
      for (let i = 0; i < 350; i++) {
        const r = mut.rand.pick(reads);
        const m = mut.mutate(mut.rand.pick(r.seeds));
        // Now and then as Prunt's failure status (its words become a vendor error).
        const status = mut.rand.chance(0.1) ? 500 : 200;
        fsim.answerNext((_method, p) => p.split('?')[0] === r.path, m, status);
        try {
          const v = await r.call();
          accepted++;
          const f = foreignPrototype(v);
          if (f) findings.add('prototype', `${r.path}: prototype of ${f}`, m);
        } catch (e) {
          refused++;
          if (!(e instanceof LinkError)) findings.add('exception', `${r.path}: ${describeErr(e)}`, m);
          else if (e.kind === 'protocol' && !e.message.trim())
            findings.add('words', `${r.path}: no words`, m);
        }
        if (fsim.waiting) findings.add('served', `${r.path}: the payload was not asked for`, m);
      }
    } finally {
      fsim.dispose();
    }
    expect(refused).toBeGreaterThan(30);
    expect(accepted).toBeGreaterThan(30);
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe("Prunt: hostile frames through the live handler and the gateway's frame reader", () => {
  it('thousands of frames: no exception, the store holds no foreign prototype, the snapshot stays sane', async () => {
    const ctx = createContext(
      { id: 'fuzz-live', name: 'Live', kind: 'prunt', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const store = createSharedStore<PruntState>(initialPruntState);
    const findings = new Findings();
    let current: Mutant | string = 'start';
    const tracker = new LinkTracker(ctx);
    const unwatch = watchBoundary(tracker, ctx.log, findings, () => current);
    for (const api of ['module', 'flat'] as const) {
      const schemaSeed = (sim['/status/schema'] ?? []).find((s) => s.name.includes(api));
      const sw = wire.statusSchemaSchema.parse(JSON.parse(schemaSeed?.text ?? '{}'));
      store.setState({ ...initialPruntState(), api, statusModel: buildStatusModel(sw) });
      let restarts = 0;
      const live = new PruntLive(ctx, store, new History(50), tracker, () => restarts++);
      const mut = new Mutator(SEED + 4 + (api === 'flat' ? 1 : 0), { depths: [20, 200, 1000] });
      for (let i = 0; i < 1500; i++) {
        const m = mut.mutate(mut.rand.pick(frames));
        current = m;
        guarded('PruntLive.message', m, findings, () => live.message(m.text));
        // The gateway reads the same bytes (which frames to replay, the watch summary).
        guarded('classifyPruntFrame', m, findings, () => classifyPruntFrame(m.text));
        const w = guarded('readPruntFrame', m, findings, () => readPruntFrame(m.text));
        const fw = w && foreignPrototype(w);
        if (fw) findings.add('prototype', `readPruntFrame: prototype of ${fw}`, m);
        if (i % 10 === 0) {
          const f = foreignPrototype(store.getState());
          if (f) findings.add('prototype', `the Prunt store: prototype of ${f}`, m);
          const p = snapshotProblem(ctx.snapshot.getState());
          if (p) findings.add('snapshot', p, m);
        }
      }
      expect(restarts).toBeGreaterThan(0);
    }
    unwatch();
    expect(ctx.snapshot.getState().link).not.toBe('connecting');
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe('Prunt: hostile input through a running session', () => {
  it('frames, status reads and config reads: alive, nothing escapes, the unsaved edit is kept', async () => {
    vi.useFakeTimers({ toFake: [...FAKE_TIMERS.toFake] });
    const id = 'fuzz-prunt';
    const fsim = new FuzzSimulator(new PruntSimulator({ id, name: 'Fuzzed printer', api: 'module' }));
    server.use(...simulatorHandlers(id, fsim));
    const ctx = createContext(
      { id, name: 'Fuzzed printer', kind: 'prunt', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
    const findings = new Findings();
    let current: Mutant | string = 'connecting';
    const unwatch = watchBoundary(session.tracker, ctx.log, findings, () => current);
    const uncaught = captureUncaught(findings, () => current);
    const step = async (ms = 50) => {
      await vi.advanceTimersByTimeAsync(ms);
    };
    const editKept = (): boolean => {
      const model = session.config.getState().model;
      return model?.changes().some((c) => c.id === FIELD && String(c.to) === '2.5') ?? false;
    };
    const check = (m: Mutant) => {
      const p = snapshotProblem(ctx.snapshot.getState());
      if (p) findings.add('snapshot', p, m);
      const f = foreignPrototype(session.store.getState());
      if (f) findings.add('prototype', `the Prunt store: prototype of ${f}`, m);
      if (!session.started) findings.add('session', 'the session stopped', m);
      if (!editKept()) findings.add('edit', 'the unsaved config edit was lost', m);
    };
    try {
      session.start();
      for (let t = 0; t < 400 && !(ctx.snapshot.getState().link === 'online' && fsim.socketsOpen > 0); t++)
        await step();
      expect(ctx.snapshot.getState().link).toBe('online');
      await session.openConfig();
      session.config.getState().model?.set(FIELD, '2.5');
      expect(editKept()).toBe(true);
      const mut = new Mutator(SEED + 6, { depths: [20, 200, 1000] });
      const seen = new Set<string>();

      // Frames into /websocket/everything, as the controller would send them.
      let sent = 0;
      for (let i = 0; i < 1000; i++) {
        const m = mut.mutate(mut.rand.pick(frames));
        current = m;
        if (guarded('socket frame', m, findings, () => fsim.sendFrame(m.text))) sent++;
        if (i % 20 === 0) {
          await step(20);
          check(m);
          seen.add(ctx.snapshot.getState().link);
        }
        for (let k = 0; k < 100 && fsim.socketsOpen === 0; k++) await step(100);
      }
      await step(100);
      expect(sent).toBeGreaterThan(950);
      expect(seen).toContain('protocol-error');
      // Mutated start times restarted the "server": the editor was read again each time.
      expect(ctx.log.store.getState().entries.some((e) => e.text.startsWith('Server restarted'))).toBe(true);

      // Reads: the status read after a command, and the reads a server restart brings.
      const reads: Array<{ path: string; seeds: Seed[]; trigger: () => void }> = [
        {
          path: '/status/values',
          seeds: seeds('/status/values', /status-values/),
          trigger: () => session.kick(),
        },
        ...(['/status/schema', '/config/schema', '/config/values'] as const).map((path) => ({
          path,
          seeds: seeds(path, new RegExp(path.slice(1).replace('/', '-'))),
          trigger: () => void fsim.sendFrame(`{"Server_Start_Time":" ${1000 + mut.rand.int(1e6)}.5"}`),
        })),
      ];
      let served = 0;
      for (let i = 0; i < 100; i++) {
        const r = mut.rand.pick(reads);
        const m = mut.mutate(mut.rand.pick(r.seeds));
        current = m;
        fsim.answerNext((_method, p) => p.split('?')[0] === r.path, m);
        const before = fsim.served;
        r.trigger();
        for (let k = 0; k < 100 && fsim.served === before; k++) await step(50);
        if (fsim.served > before) served++;
        await step(50);
        check(m);
        for (let k = 0; k < 100 && fsim.socketsOpen === 0; k++) await step(100);
      }
      expect(served).toBeGreaterThan(85);
      expect(session.started).toBe(true);

      // After the storm the controller restarts and answers truly: its ticks bring the machine
      // back, the status schema and the editor are read again, and the edit is still there.
      current = 'recovery';
      expect(fsim.waiting).toBe(false);
      fsim.sendFrame('{"Server_Start_Time":" 99999999.5"}');
      for (let t = 0; t < 200; t++) {
        const ready =
          session.config.getState().phase === 'ready' && session.store.getState().api === 'module';
        if (ready && ctx.snapshot.getState().link === 'online') break;
        await step(100);
      }
      expect(ctx.snapshot.getState().link).toBe('online');
      expect(session.store.getState().api).toBe('module');
      expect(session.config.getState().phase).toBe('ready');
      expect(editKept()).toBe(true);
    } finally {
      uncaught();
      unwatch();
      session.stop();
      fsim.dispose();
    }
    expect(findings.count, report(findings)).toBe(0);
  }, 90_000);
});
