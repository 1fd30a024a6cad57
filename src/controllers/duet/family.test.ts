import { describe, expect, it } from 'vitest';
import { duetFamily } from './family';

describe('duetFamily', () => {
  const hooks = duetFamily.gateway!.session!;
  const q = (s = '') => new URLSearchParams(s);

  it('has the gateway hold the DSF session (no injectSecrets: connect never leaves the browser)', () => {
    expect(duetFamily.gateway?.injectSecrets).toBeUndefined();
    expect(hooks.intercept({ method: 'GET', path: '/machine/connect', query: q() })).toEqual({
      kind: 'open',
    });
    expect(hooks.intercept({ method: 'GET', path: '/machine/connect', query: q('password=typed') })).toEqual({
      kind: 'open',
      credentials: { password: 'typed' },
    });
    expect(hooks.intercept({ method: 'GET', path: '/machine/disconnect', query: q() })).toEqual({
      kind: 'close',
    });
    expect(hooks.intercept({ method: 'GET', path: '/machine/status', query: q() })).toBeNull();
    // Any form ASP.NET routes to connect/disconnect, any method: never forwarded.
    for (const path of ['/Machine/Connect', '/machine/connect/', '/machine//%63onnect', '/MACHINE/CONNECT'])
      expect(hooks.intercept({ method: 'GET', path, query: q('PassWord=p') })).toEqual({
        kind: 'open',
        credentials: { password: 'p' },
      });
    expect(hooks.intercept({ method: 'HEAD', path: '/machine/connect', query: q() })).toEqual({
      kind: 'open',
    });
    expect(hooks.intercept({ method: 'POST', path: '/machine/Disconnect/', query: q() })).toEqual({
      kind: 'close',
    });
    expect(hooks.intercept({ method: 'GET', path: '/machine/connection', query: q() })).toBeNull();
    expect(hooks.intercept({ method: 'GET', path: '/machine/connect%2Fx', query: q() })).toBeNull();
    expect(hooks.isExpired(403)).toBe(true);
    expect(hooks.isExpired(404)).toBe(false);
  });

  it('drops any key the browser sent (any letter case) and adds the gateway’s', () => {
    const http = {
      headers: { 'x-session-key': 'browser', 'X-SESSION-KEY': 'b2' },
      query: q('SessionKey=b&sessionKey=c&x=1'),
    };
    hooks.apply(http, 'gw-key');
    expect(http.headers).toEqual({ 'x-session-key': 'gw-key' });
    expect(http.query.toString()).toBe('x=1');
    const none = { headers: { 'x-session-key': 'browser' }, query: q() };
    hooks.apply(none, null);
    expect(none.headers).toEqual({});
    const ws = { headers: { 'x-session-key': 'browser' }, query: q('sessionKey=browser') };
    hooks.applyWs(ws, 'gw-key');
    expect(ws.headers).toEqual({});
    expect(ws.query.getAll('sessionKey')).toEqual(['gw-key']);
  });

  it('opens with the password and answers the browser without the key', async () => {
    const calls: string[] = [];
    const ok = await hooks.open(
      async (method, pq) => {
        calls.push(`${method} ${pq}`);
        return {
          status: 200,
          headers: { 'content-type': 'application/json' },
          body: JSON.stringify({ sessionKey: 'k-123', SESSIONKEY: 'k-123', apiLevel: 1 }),
        };
      },
      { password: 'p w&' },
    );
    expect(calls).toEqual(['GET /machine/connect?password=p+w%26']);
    expect(ok.ok && ok.key).toBe('k-123');
    expect(JSON.parse(ok.answer.body)).toEqual({ apiLevel: 1 });
    const numeric = await hooks.open(
      async () => ({ status: 200, headers: {}, body: '{"sessionKey":42}' }),
      undefined,
    );
    expect(numeric.ok && numeric.key).toBe('42');
    const none = await hooks.open(async (_m, pq) => {
      expect(pq).toBe('/machine/connect');
      return { status: 200, headers: {}, body: '{}' };
    }, undefined);
    expect(none.ok && none.key).toBeNull();
    const refused = await hooks.open(async () => ({ status: 403, headers: {}, body: 'Invalid password' }), {
      password: 'x',
    });
    expect(refused).toEqual({ ok: false, answer: { status: 403, headers: {}, body: 'Invalid password' } });
  });

  it('is Node-safe and makes a duet simulator', () => {
    const sim = duetFamily.createSimulator({ id: 'x', name: 'x' });
    expect(sim.kind).toBe('duet');
    expect(sim.controls?.().map((c) => c.id)).toContain('box-7');
    sim.dispose();
    expect(duetFamily.accessNeedsBody?.('POST', '/machine/code')).toBe(true);
  });
});
