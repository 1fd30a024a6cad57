// @vitest-environment happy-dom
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import type { SessionContext } from '../../fleet/contract';
import { FaultySimulator } from '../../fleet/sim';
import { DuetSession } from './session';
import { DuetSimulator } from './sim/simulator';

let sim: DuetSimulator;
const server = setupServer();
let ctx: SessionContext;
let session: DuetSession;

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(async () => {
  sim = new DuetSimulator({ id: 'du', name: 'duet-sim', tickMs: 250 });
  server.resetHandlers(...simulatorHandlers('du', sim));
  ctx = createContext(
    { id: 'du', name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  session = new DuetSession(ctx);
  session.client.sessionKey = await session.client.connect();
  // The command runner only sends while the link is online.
  ctx.snapshot.setState({ link: 'online' });
});
afterEach(() => {
  session.stop();
  sim.dispose();
});

describe('uploads', () => {
  it('uploads a job file with progress, timeModified and the session key', async () => {
    const body = 'G28\n'.repeat(20_000);
    const file = new Blob([body]);
    const seen: number[] = [];
    const unsub = session.store.subscribe((s) => {
      const u = s.uploads[0];
      if (u) seen.push(u.loaded);
    });
    await ctx.commands.run(session.uploadCommandFor('0:/gcodes'), {
      file,
      name: 'big.gcode',
      dir: '0:/gcodes',
    });
    unsub();
    expect(sim.fs.text('0:/gcodes/big.gcode')).toBe(body);
    const u = session.store.getState().uploads[0]!;
    expect(u.status).toBe('done');
    expect(u.loaded).toBe(file.size);
    expect(seen.length).toBeGreaterThan(1);
    const listing = sim.fs.list('0:/gcodes')!;
    expect(listing.find((e) => e.name === 'big.gcode')?.size).toBe(body.length);
  });

  it('an operator may not use the supervisor upload (system folder)', async () => {
    const cmd = session.uploadCommandFor('0:/sys');
    expect(cmd.role).toBe('supervisor');
    await expect(
      ctx.commands.run(cmd, { file: new Blob(['x']), name: 'config.g', dir: '0:/sys' }),
    ).rejects.toThrow(/supervisor/);
  });

  it('cancels an upload', async () => {
    const slow = new FaultySimulator(sim);
    slow.setFaults({ latencyMs: 300 });
    server.resetHandlers(...simulatorHandlers('du', slow));
    const file = new Blob(['G1 X1\n'.repeat(50_000)]);
    const p = ctx.commands.run(session.uploadCommandFor('0:/gcodes'), {
      file,
      name: 'cancel-me.gcode',
      dir: '0:/gcodes',
    });
    const id = session.store.getState().uploads.at(-1)!.id;
    session.cancelUpload(id);
    await expect(p).rejects.toThrow(/cancelled/i);
    expect(session.store.getState().uploads.at(-1)?.status).toBe('cancelled');
    expect(
      ctx.log.store.getState().entries.some((e) => e.level === 'error' && /cancelled/i.test(e.text)),
    ).toBe(true);
  });
});
