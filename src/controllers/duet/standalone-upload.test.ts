// @vitest-environment happy-dom
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import type { SessionContext } from '../../fleet/contract';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { crc32Hex } from './crc32';
import { rrQuery } from './rrf-connect';
import { DuetSession } from './session';
import { RrfSimulator } from './sim/standalone';

/**
 * The standalone client against the in-page simulator (msw, no gateway): `/machine/connect` is
 * not there (404), so the page asks `rr_connect?sessionKey=yes` itself and sends the key in
 * `X-Session-Key`; uploads go by `rr_upload` with the payload's crc32 and progress, and
 * `{"err":1}` is a failed upload on screen.
 */

let sim: RrfSimulator;
const server = setupServer();
let ctx: SessionContext;
let session: DuetSession;
const seen: Array<{ url: string; key: string | null }> = [];

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(async () => {
  sim = new RrfSimulator({ id: 'ru', name: 'rrf-sim', tickMs: 250 });
  const inner = sim.fetch.bind(sim);
  sim.fetch = (req, path) => {
    seen.push({ url: path, key: req.headers.get('X-Session-Key') });
    return inner(req, path);
  };
  server.resetHandlers(...simulatorHandlers('ru', sim));
  ctx = createContext(
    { id: 'ru', name: 'Duet 2', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  session = new DuetSession(ctx);
  seen.length = 0;
  await session.client.connect();
  ctx.snapshot.setState({ link: 'online' });
});
afterEach(() => {
  session.stop();
  sim.dispose();
});

async function until(pred: () => boolean, ms = 10_000): Promise<void> {
  const end = Date.now() + ms;
  while (!pred()) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await new Promise((r) => setTimeout(r, 20));
  }
}

describe('standalone client (in-page simulator)', () => {
  it('connects by rr_connect with sessionKey=yes and sends the key on every request', async () => {
    expect(session.client.api).toBe('standalone');
    const connect = seen.find((s) => s.url.startsWith('/rr_connect'));
    const q = new URLSearchParams(connect?.url.split('?')[1]);
    expect(q.get('sessionKey')).toBe('yes');
    expect(q.get('time')).toMatch(/^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d$/);
    expect(session.client.sessionKey).toMatch(/^\d+$/);
    await session.client.rrf.poll();
    const after = seen.filter((s) => !s.url.startsWith('/machine/') && !s.url.startsWith('/rr_connect'));
    expect(after.length).toBeGreaterThan(1);
    for (const s of after) expect(s.key, s.url).toBe(session.client.sessionKey);
  });

  it('uploads a job file by rr_upload with its crc32 and progress', async () => {
    const body = 'G1 X1 Y1\n'.repeat(20_000);
    const progress: number[] = [];
    const unsub = session.store.subscribe((s) => {
      const u = s.uploads[0];
      if (u) progress.push(u.loaded);
    });
    await ctx.commands.run(session.uploadCommandFor('0:/gcodes'), {
      file: new Blob([body]),
      name: 'a b.gcode',
      dir: '0:/gcodes',
    });
    unsub();
    expect(sim.printer.fs.text('0:/gcodes/a b.gcode')).toBe(body);
    const up = seen.find((s) => s.url.startsWith('/rr_upload'));
    const q = new URLSearchParams(up?.url.split('?')[1]);
    expect(q.get('name')).toBe('0:/gcodes/a b.gcode');
    expect(up?.url).toContain('a%20b.gcode'); // never "+" for a space
    expect(q.get('crc32')).toBe(crc32Hex(new TextEncoder().encode(body)));
    expect(session.store.getState().uploads[0]?.status).toBe('done');
    expect(progress.length).toBeGreaterThan(1);
  });

  it('shows {"err":1} from rr_upload as a failed upload, in the row and the log', async () => {
    sim.printer.fs.mkdirs('0:/gcodes/taken.gcode'); // a folder of that name: the board refuses
    await expect(
      ctx.commands.run(session.uploadCommandFor('0:/gcodes'), {
        file: new Blob(['G28\n']),
        name: 'taken.gcode',
        dir: '0:/gcodes',
      }),
    ).rejects.toThrow(/err 1/);
    const u = session.store.getState().uploads.at(-1);
    expect(u?.status).toBe('failed');
    expect(u?.error).toMatch(/err 1/);
    expect(ctx.log.store.getState().entries.some((e) => e.level === 'error' && /err 1/.test(e.text))).toBe(
      true,
    );
  });

  it('a board that stops answering is the link down within 5 s, and back when it answers', async () => {
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online' && session.store.getState().model !== null);
    let hold = true;
    const inner = sim.fetch.bind(sim);
    sim.fetch = async (req, path) => {
      while (hold) await new Promise((r) => setTimeout(r, 50));
      return inner(req, path);
    };
    const t0 = Date.now();
    await until(() => /No answer from the Duet/.test(ctx.snapshot.getState().problem?.message ?? ''), 8000);
    expect(Date.now() - t0).toBeLessThan(6000);
    expect(ctx.snapshot.getState().problem?.message).toMatch(/rr_model/);
    hold = false;
    await until(() => ctx.snapshot.getState().link === 'online', 15_000);
  }, 30_000);

  it('encodes query values with %20, never +', () => {
    expect(rrQuery({ gcode: 'M32 "0:/gcodes/a+b.gcode"', x: undefined })).toBe(
      '?gcode=M32%20%220%3A%2Fgcodes%2Fa%2Bb.gcode%22',
    );
  });
});
