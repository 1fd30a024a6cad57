import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { xtoolFamily } from '../src/controllers/xtool/family';
import type { FamilyDescriptor } from '../src/fleet/contract';
import type { Simulator, SimControl } from '../src/fleet/sim';
import { startGateway, tempDir } from './test-util';

/**
 * The gateway watches a machine nobody looks at (watch.ts through the real gateway): a simulated
 * xTool with no browser open; its job start and a flame reach the audit log.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function until(what: string, ok: () => boolean | Promise<boolean>, ms = 8000): Promise<void> {
  const end = Date.now() + ms;
  while (!(await ok())) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 20));
  }
}

describe('the gateway’s watch, with no viewer', () => {
  it('holds the shared stream, polls, and writes job starts and alarms to the audit log', async () => {
    let sim: Simulator | null = null;
    const sharing = xtoolFamily.gateway?.sharing;
    const watch = sharing?.watch;
    if (!sharing || !watch) throw new Error('the xTool family declares no watch');
    const family: FamilyDescriptor = {
      ...xtoolFamily,
      gateway: { ...xtoolFamily.gateway, sharing: { ...sharing, watch: { ...watch, everyMs: 150 } } },
      createSimulator: (o) => (sim = xtoolFamily.createSimulator(o)),
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 'x1', name: 'Laser', kind: 'xtool', simulated: true, url: null, wsUrl: null, secrets: {} },
        ],
      },
      families: { xtool: family },
      dataDir: t.dir,
      env: {},
      watch: true,
    });
    cleanups.push(gw.close);
    await until('the watch holds the laser’s socket', () => gw.gw.streamStats('x1').open === 1);
    const auditLines = async (): Promise<Array<{ type: string; label?: string; detail?: string }>> => {
      await gw.gw.audit.flush();
      const file = path.join(t.dir, 'audit.jsonl');
      if (!existsSync(file)) return [];
      return readFileSync(file, 'utf8')
        .split('\n')
        .filter(Boolean)
        .map((l) => JSON.parse(l) as { type: string; label?: string; detail?: string });
    };
    const control = (id: string): SimControl => {
      const s: Simulator | null = sim;
      const c = s?.controls?.().find((x) => x.id === id);
      if (!c) throw new Error(`no control ${id}`);
      return c;
    };
    const run = (id: string): void => control(id).run();
    run('demo');
    let seen: Array<{ type: string; label?: string; detail?: string }> = [];
    await until('job started in the audit log', async () => {
      seen = await auditLines();
      return seen.some((e) => e.type === 'machine' && e.label === 'job started');
    });
    run('flame');
    await until('the flame in the audit log', async () => {
      seen = await auditLines();
      return seen.some((e) => e.type === 'machine' && e.label === 'alarm');
    });
    expect(seen.find((e) => e.label === 'alarm')?.detail).toMatch(/flame/i);
    // Nobody opened a browser socket: the one upstream socket is the watch's.
    expect(gw.gw.streamStats('x1').joined).toBe(0);
  });
});
