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
import { DuetModel } from './model';
import { applyPatch, isObject, type JsonObject } from './patch';
import { DuetSession } from './session';
import { DuetSimulator } from './sim/simulator';
import { snapshotOf } from './snapshot';
import * as wire from './wire';

// Pure CPU work: on a loaded 2-core machine a case takes 20–35 s; the time bound is not the test.
vi.setConfig({ testTimeout: 90_000 });

/**
 * Hostile input for the Duet family (issue 15): thousands of payloads mutated from the object
 * models and DSF patches in tests/fixtures/duet and from the simulator's answers, through the
 * wire schemas, the patch merge, the validated model and the snapshot, and as frames on a running
 * session's `WS /machine`. Nothing may throw past the boundary, no `__proto__` key may become a
 * prototype (of the raw model the patches merge into, or of anything parsed), and the session
 * stays alive. Seeded: a failure names its payload and replays.
 */

const SEED = 0x15_0002;

const MODELS = fixtureFiles('duet/object-model');
const PATCHES = fixtureFiles('duet/patches');
const HEIGHTMAP = fixtureFiles('duet/files', ['.csv']);

/** Patches as DSF sends them: the fixtures, and each top-level part of a model on its own. */
function patchSeeds(): Seed[] {
  const out: Seed[] = [...PATCHES];
  for (const m of MODELS) {
    const model = JSON.parse(m.text) as Record<string, unknown>;
    for (const [k, v] of Object.entries(model))
      out.push({ name: `${m.name}#${k}`, text: JSON.stringify({ [k]: v }) });
  }
  return out;
}
const PATCH_SEEDS = patchSeeds();

/** Answers of the simulator to the reads the session makes (listings, file info). */
async function simSeeds(): Promise<{ dir: Seed[]; fileInfo: Seed[]; connect: Seed[] }> {
  const sim = new DuetSimulator({ id: 'seed', name: 'Seed Duet' });
  try {
    const ask = async (p: string, headers: Record<string, string> = {}): Promise<string> =>
      (await sim.fetch(new Request(`http://sim${p}`, { headers }), p)).text();
    const connect = await ask('/machine/connect');
    const key = (JSON.parse(connect) as { sessionKey?: string }).sessionKey ?? '';
    const h = { 'X-Session-Key': key };
    const dir = await ask('/machine/directory/0%3A%2Fgcodes', h);
    const names = (JSON.parse(dir) as Array<{ name?: string; type?: string }>).filter((e) => e.type === 'f');
    const fileInfo: Seed[] = [];
    for (const e of names.slice(0, 3))
      fileInfo.push({
        name: `fileinfo ${e.name ?? ''}`,
        text: await ask(
          `/machine/fileinfo/${encodeURIComponent(`0:/gcodes/${e.name ?? ''}`)}?readThumbnailContent=true`,
          h,
        ),
      });
    return {
      dir: [{ name: 'directory 0:/gcodes', text: dir }],
      fileInfo,
      connect: [{ name: 'connect', text: connect }],
    };
  } finally {
    sim.dispose();
  }
}

let seeds: Awaited<ReturnType<typeof simSeeds>>;
const { server } = fuzzHarness(async () => {
  seeds = await simSeeds();
});

function parseObject(text: string): JsonObject | null {
  try {
    const v: unknown = JSON.parse(text);
    return isObject(v) ? v : null;
  } catch {
    return null;
  }
}

describe('Duet: hostile payloads through the parsers', () => {
  it('has seeds', () => {
    expect(MODELS.length).toBeGreaterThan(0);
    expect(PATCHES.length).toBeGreaterThan(10);
    expect(seeds.fileInfo.length).toBeGreaterThan(0);
  });

  it('wire schemas and the height map: no exception, no prototype from a payload', () => {
    const mut = new Mutator(SEED);
    const findings = new Findings();
    const targets: Array<{ name: string; schema: z.ZodMiniType; seeds: Seed[] }> = [
      { name: 'object model', schema: wire.objectModelSchema, seeds: MODELS },
      { name: 'connect', schema: wire.connectResponse, seeds: seeds.connect },
      { name: 'directory', schema: wire.directoryListing, seeds: seeds.dir },
      { name: 'file info', schema: wire.parsedFileInfoSchema, seeds: seeds.fileInfo },
      {
        name: 'message',
        schema: wire.messageSchema,
        seeds: PATCHES.filter((p) => p.name.includes('messages')),
      },
    ];
    for (let i = 0; i < 1500; i++) {
      const t = mut.rand.pick(targets);
      parseChecked(t.name, t.schema, mut.mutate(mut.rand.pick(t.seeds)), findings);
    }
    for (let i = 0; i < 300; i++) {
      const m = mut.mutate(mut.rand.pick(HEIGHTMAP));
      guarded('parseHeightMap', m, findings, () => {
        try {
          return wire.parseHeightMap(m.text);
        } catch (e) {
          // A height map it cannot read is refused in words (an Error), never a TypeError.
          if (e instanceof Error && e.constructor === Error) return null;
          throw e;
        }
      });
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('a patch nested deeper than the stack is refused, not thrown', () => {
    const findings = new Findings();
    const full = parseObject(MODELS[0]?.text ?? '{}') ?? {};
    for (const kind of ['object', 'array'] as const) {
      const m: Mutant = {
        text: `{"sensors":${deepText(VERY_DEEP, kind)}}`,
        how: `sensors nested ${VERY_DEEP} deep (${kind})`,
      };
      const patch = parseObject(m.text);
      if (!patch) throw new Error('the deep patch does not parse');
      guarded('applyPatch', m, findings, () => applyPatch(full, patch));
      const model = new DuetModel();
      model.full(full);
      guarded('DuetModel.patch', m, findings, () => model.patch(patch));
    }
    expect(findings.count, report(findings)).toBe(0);
  });

  it('patches merged into the model, validated and summarised: no exception, no prototype', () => {
    // Nesting stays within the stack here (the test above goes beyond it): each overflow costs 0.5 s.
    const mut = new Mutator(SEED + 1, { depths: [20, 200, 1000], veryDeep: 0 });
    const findings = new Findings();
    for (let run = 0; run < 16; run++) {
      const model = new DuetModel();
      const fullSeed = mut.rand.pick(MODELS);
      // Half of the runs start from a mutated full model.
      const fm: Mutant = run % 2 === 0 ? { text: fullSeed.text, how: fullSeed.name } : mut.mutate(fullSeed);
      let raw: JsonObject = parseObject(fm.text) ?? {};
      guarded('DuetModel.full', fm, findings, () => model.full(raw));
      for (let i = 0; i < 120; i++) {
        const m = mut.mutate(mut.rand.pick(PATCH_SEEDS));
        const patch = parseObject(m.text);
        if (!patch) continue;
        const merged = guarded('applyPatch', m, findings, () => applyPatch(raw, patch));
        if (merged) {
          const f = foreignPrototype(merged.model);
          if (f) findings.add('prototype', `applyPatch: a __proto__ key became the prototype of ${f}`, m);
          raw = merged.model;
        }
        const r = guarded('DuetModel.patch', m, findings, () => model.patch(patch));
        if (r?.ok) {
          const f = foreignPrototype(r.model);
          if (f) findings.add('prototype', `validated model: prototype of ${f}`, m);
          const snap = guarded('snapshotOf', m, findings, () => snapshotOf(r.model, () => 0));
          const p = snap?.job?.progress;
          if (p !== null && p !== undefined && !(Number.isFinite(p) && p >= 0 && p <= 1))
            findings.add('snapshot', `job progress ${p}`, m);
        }
      }
    }
    expect(findings.count, report(findings)).toBe(0);
  });
});

describe('Duet: hostile frames through a running session', () => {
  it('patches on WS /machine: the session stays alive, nothing escapes, the snapshot stays sane', async () => {
    vi.useFakeTimers({ toFake: [...FAKE_TIMERS.toFake] });
    const id = 'fuzz-duet';
    const sim = new FuzzSimulator(new DuetSimulator({ id, name: 'Fuzzed Duet', tickMs: 250 }));
    server.use(...simulatorHandlers(id, sim));
    const ctx = createContext(
      { id, name: 'Fuzzed Duet', kind: 'duet', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'fuzz', role: 'supervisor' }) },
    );
    const session = new DuetSession(ctx);
    const findings = new Findings();
    let current: Mutant | string = 'connecting';
    const unwatch = watchBoundary(session.tracker, ctx.log, findings, () => current);
    const uncaught = captureUncaught(findings, () => current);
    const step = async (ms = 50) => {
      await vi.advanceTimersByTimeAsync(ms);
    };
    try {
      session.start();
      for (let t = 0; t < 400 && !(ctx.snapshot.getState().link === 'online' && sim.socketsOpen > 0); t++)
        await step();
      expect(ctx.snapshot.getState().link).toBe('online');
      const mut = new Mutator(SEED + 2, { depths: [20, 200, 1000], veryDeep: 0 });
      const seen = new Set<string>();
      let sent = 0;
      // Two frames nested beyond the stack, then the storm.
      for (const kind of ['object', 'array'] as const) {
        const m: Mutant = {
          text: `{"sensors":${deepText(VERY_DEEP, kind)}}`,
          how: `frame nested ${VERY_DEEP} deep (${kind})`,
        };
        current = m;
        sim.sendFrame(m.text);
        await step(50);
        for (let k = 0; k < 200 && sim.socketsOpen === 0; k++) await step(100);
      }
      for (let i = 0; i < 1200; i++) {
        const m = mut.mutate(mut.rand.pick(PATCH_SEEDS));
        current = m;
        if (guarded('socket frame', m, findings, () => sim.sendFrame(m.text))) sent++;
        if (i % 10 === 0) await step(20);
        const p = snapshotProblem(ctx.snapshot.getState());
        if (p) findings.add('snapshot', p, m);
        if (!session.started) findings.add('session', 'the session stopped', m);
        seen.add(ctx.snapshot.getState().link);
        // A socket the session gave up on reconnects: wait for it rather than write into nothing.
        for (let k = 0; k < 200 && sim.socketsOpen === 0; k++) await step(100);
      }
      expect(sent).toBeGreaterThan(1000);
      expect(seen).toContain('protocol-error');
      expect(session.started).toBe(true);
      // After the storm, the real simulator's frames bring the machine back.
      current = 'recovery';
      for (let t = 0; t < 300 && ctx.snapshot.getState().link !== 'online'; t++) await step(100);
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
