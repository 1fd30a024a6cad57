import { ws } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it, vi } from 'vitest';
import { LinkTracker } from './contract';
import { LinkError } from './errors';
import { createContext } from './fleet';
import { alwaysVisible, SocketLink } from './link';

const link = ws.link('ws://shopdeck.test/machines/m1/*');
const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => server.resetHandlers());
afterAll(() => server.close());

const until = async (cond: () => boolean) => {
  for (let i = 0; i < 200 && !cond(); i++) await new Promise((r) => setTimeout(r, 5));
  expect(cond()).toBe(true);
};

describe('SocketLink', () => {
  it('reconnects after the server closes, and never replays what was sent while closed', async () => {
    const received: string[] = [];
    let connections = 0;
    server.use(
      link.addEventListener('connection', ({ client }) => {
        connections++;
        client.addEventListener('message', (e) => received.push(String(e.data)));
        if (connections === 1) setTimeout(() => client.close(1011, 'service down'), 5);
      }),
    );
    const closes: number[] = [];
    const sock = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/m1/ws',
      onMessage: () => undefined,
      onClose: (code) => {
        closes.push(code);
      },
      backoff: { baseMs: 10, maxMs: 20 },
    });
    await until(() => closes.length === 1);
    expect(sock.open).toBe(false);
    expect(sock.send('PAUSE')).toBe(false); // not buffered
    await until(() => connections === 2 && sock.open);
    expect(sock.send('hello')).toBe(true);
    await until(() => received.length === 1);
    expect(received).toEqual(['hello']);
    sock.close();
  });
});

describe('LinkTracker', () => {
  it('goes reconnecting, then offline after repeated failures, with growing delays', () => {
    const ctx = createContext(
      { id: 'm1', name: 'M1', kind: 'xtool', simulated: false },
      { visibility: alwaysVisible, now: () => 1000 },
    );
    const t = new LinkTracker(ctx);
    vi.spyOn(Math, 'random').mockReturnValue(1);
    const d1 = t.fail(new LinkError('network', 'down'));
    expect(ctx.snapshot.getState().link).toBe('reconnecting');
    const d2 = t.fail(new LinkError('timeout', 'slow'));
    expect(d2).toBeGreaterThan(d1);
    t.fail(new LinkError('network', 'down'));
    expect(ctx.snapshot.getState().link).toBe('offline');
    expect(ctx.snapshot.getState().activity).toBe('offline');
    t.ok({ activity: 'idle' });
    expect(ctx.snapshot.getState()).toMatchObject({
      link: 'online',
      problem: null,
      activity: 'idle',
      updatedAt: 1000,
    });
    t.fail(new LinkError('protocol', 'bad', { path: 'progress' }));
    expect(ctx.snapshot.getState()).toMatchObject({ link: 'protocol-error', problem: { path: 'progress' } });
    vi.restoreAllMocks();
  });
});
