import { http, HttpResponse } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it } from 'vitest';
import { discoverLasers, machineEntry } from './discover';

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => server.resetHandlers());
afterAll(() => server.close());

const URL = 'http://shopdeck.test/api/discover/xtool';

describe('discoverLasers', () => {
  it('parses the gateway answer', async () => {
    server.use(
      http.get(URL, () =>
        HttpResponse.json({
          replies: [
            { requestId: 7, ip: '127.0.0.1', name: 'xTool D1 Pro', version: '40.31.006.01', via: 'tcp' },
            { requestId: '7', ip: '127.0.0.1', name: '', version: 'V40.32.013.2224.01', via: 'udp' },
          ],
          broadcast: '127.0.0.1',
        }),
      ),
    );
    const r = await discoverLasers();
    expect(r.broadcast).toBe('127.0.0.1');
    expect(r.replies.map((x) => x.via)).toEqual(['tcp', 'udp']);
    expect(r.replies[1]?.requestId).toBe(7);
  });

  it('reports a malformed answer with the path that failed', async () => {
    server.use(http.get(URL, () => HttpResponse.json({ replies: [{ name: 'x' }] })));
    await expect(discoverLasers()).rejects.toMatchObject({ kind: 'protocol', path: 'replies.0.ip' });
  });

  it('reports HTTP errors', async () => {
    server.use(http.get(URL, () => new HttpResponse('forbidden', { status: 403 })));
    await expect(discoverLasers()).rejects.toMatchObject({ kind: 'http' });
  });
});

describe('machineEntry', () => {
  it('makes a valid, unique machines-file entry', () => {
    const r = { ip: '10.0.0.50', name: 'xTool D1 Pro', version: '', via: 'udp' };
    expect(machineEntry(r)).toEqual({
      id: 'xtool-d1-pro',
      name: 'xTool D1 Pro',
      kind: 'xtool',
      url: 'http://10.0.0.50:8080',
    });
    expect(machineEntry(r, new Set(['xtool-d1-pro'])).id).toBe('xtool-d1-pro-2');
    const nameless = machineEntry({ ...r, name: '' });
    expect(nameless).toMatchObject({ id: 'xtool-10-0-0-50', name: 'xTool at 10.0.0.50' });
    expect(nameless.id).toMatch(/^[a-z0-9-]{1,40}$/);
  });
});
