import { setupServer } from 'msw/node';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { simulatorHandlers } from './msw';
import { jsonResponse, type Simulator } from './sim';

const sim: Simulator = {
  kind: 'xtool',
  fetch: async (_req, path) => jsonResponse({ path }),
  socket: (path, sock) => {
    sock.send(`hello ${path}`);
    return { message: (d) => sock.send(`echo ${d}`), close: () => undefined };
  },
  dispose: () => undefined,
};

const server = setupServer(...simulatorHandlers('m1', sim));
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

describe('simulatorHandlers', () => {
  it('routes HTTP to the simulator with the controller path', async () => {
    const r = await fetch('http://shopdeck.test/machines/m1/progress?x=1');
    expect(await r.json()).toEqual({ path: '/progress?x=1' });
  });
  it('routes WebSocket frames both ways', async () => {
    const sock = new globalThis.WebSocket('ws://shopdeck.test/machines/m1/ws');
    const got: string[] = [];
    await new Promise<void>((resolve) => {
      sock.onmessage = (e) => {
        got.push(String(e.data));
        if (got.length === 1) sock.send('ping');
        if (got.length === 2) resolve();
      };
    });
    expect(got).toEqual(['hello /ws', 'echo ping']);
    sock.close();
  });
});

describe('simulatorHandlers at the root socket path', () => {
  it('routes a socket opened at /machines/<id>/ (xTool listens at the root of :8081)', async () => {
    const sock = new globalThis.WebSocket('ws://shopdeck.test/machines/m1/');
    const first = await new Promise<string>((resolve) => {
      sock.onmessage = (e) => resolve(String(e.data));
    });
    expect(first).toBe('hello /');
    sock.close();
  });
});
