import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import type { UpstreamAnswer, UpstreamRequest } from '../../fleet/contract';
import { credentialsOf, jwtExpiry, touchcutHeldSession as hooks, withoutToken } from './gateway';

/** A JWT-shaped token whose `exp` is `exp` (seconds). */
function jwt(exp: number, extra = 'sig'): string {
  const b64 = (o: unknown) =>
    btoa(JSON.stringify(o)).replace(/=+$/, '').replace(/\+/g, '-').replace(/\//g, '_');
  return `${b64({ alg: 'HS256' })}.${b64({ sub: 'operator', exp })}.${extra}`;
}

const intercept = (method: string, raw: string) => {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(t.error);
  return hooks.intercept({ method, path: t.path, query: t.query });
};

const answer = (status: number, body: unknown): UpstreamAnswer => ({
  status,
  headers: { 'content-type': 'application/json; charset=utf-8' },
  body: typeof body === 'string' ? body : JSON.stringify(body),
});

describe('touchcut held login hooks (gateway.ts)', () => {
  it('answers every form of auth itself; only the documented reads and others are forwarded', () => {
    for (const p of ['/rest/v1/auth', '/REST/v1/Auth/', '//rest//v1//auth', '/rest/v1/au%74h'])
      expect(intercept('POST', p)?.kind, p).toBe('open');
    expect(intercept('GET', '/rest/v1/auth')).toEqual({ kind: 'open' });
    expect(intercept('HEAD', '/rest/v1/auth')).toEqual({ kind: 'open' });
    expect(intercept('DELETE', '/rest/v1/auth')).toEqual({ kind: 'close', end: true });
    expect(intercept('POST', '/rest/v1/auth/change-password')).toEqual({ kind: 'exchange' });
    expect(intercept('POST', '/rest/v1/Auth/Change-Password/')).toEqual({ kind: 'exchange' });
    // Nothing else under auth reaches TouchCut (it could mint a token the gateway does not hold).
    for (const [m, p] of [
      ['PUT', '/rest/v1/auth'],
      ['GET', '/rest/v1/auth/change-password'],
      ['POST', '/rest/v1/auth/other'],
      ['POST', '/rest/v1/auth;x'],
      ['POST', '/rest/v1/authx'],
      ['POST', '/rest/v1/auth.json'],
    ] as const)
      expect(intercept(m, p), `${m} ${p}`).toMatchObject({ kind: 'answer', answer: { status: 405 } });
    for (const p of ['/rest/v1/status', '/rest/v1/screenshot', '/rest/v1/machine-info', '/', '/auth'])
      expect(intercept('GET', p), p).toBeNull();
  });

  it('reads the credentials from a form or a JSON body', () => {
    expect(credentialsOf('username=op&password=p%26w', 'application/x-www-form-urlencoded')).toEqual({
      username: 'op',
      password: 'p&w',
    });
    expect(credentialsOf('{"username":"op","password":"pw"}', 'application/json')).toEqual({
      username: 'op',
      password: 'pw',
    });
    expect(credentialsOf('', '')).toEqual({ username: '', password: '' });
  });

  it('logs in upstream with a form; the answer has the user and expiry, never the token', async () => {
    const token = jwt(2_000_000_000);
    const calls: Array<{ method: string; pq: string; headers?: Record<string, string>; body?: string }> = [];
    const upstream: UpstreamRequest = async (method, pq, headers, body) => {
      calls.push({ method, pq, headers, body });
      return answer(200, { success: 'true', token, extra: 1 });
    };
    const r = await hooks.open(upstream, { username: 'operator', password: 'p w&' });
    expect(calls).toEqual([
      {
        method: 'POST',
        pq: '/rest/v1/auth',
        headers: { 'content-type': 'application/x-www-form-urlencoded', accept: 'application/json' },
        body: 'username=operator&password=p+w%26',
      },
    ]);
    expect(r.ok && r.key).toBe(token);
    expect(JSON.parse(r.answer.body)).toEqual({
      success: 'true',
      extra: 1,
      loggedIn: true,
      user: 'operator',
      expiresAt: 2_000_000_000_000,
    });
    expect(r.answer.body).not.toContain(token);
    // No credentials: no request, "not logged in".
    const none = await hooks.open(async () => {
      throw new Error('no request expected');
    }, undefined);
    expect(none).toMatchObject({ ok: true, key: null });
    expect(JSON.parse(none.answer.body)).toEqual({ loggedIn: false, user: null, expiresAt: null });
  });

  it('a refused login is TouchCut’s answer as it is (without any token field)', async () => {
    const wrong = await hooks.open(async () => answer(400, { code: '102', msg: 'Invalid Password' }), {
      username: 'operator',
      password: 'x',
    });
    expect(wrong).toEqual({ ok: false, answer: answer(400, { code: '102', msg: 'Invalid Password' }) });
    const odd = await hooks.open(async () => answer(200, { success: 'false', token: 'leak.y.z' }), {
      username: 'operator',
      password: 'x',
    });
    expect(odd.ok).toBe(false);
    expect(odd.answer.body).not.toContain('leak.y.z');
  });

  it('drops every credential the browser sent and adds the held JWT', () => {
    const h: Record<string, string> = {
      Authorization: 'Bearer forged',
      COOKIE: '__Secure-jwt=forged',
      'x-touchcut-api-key': 'forged',
      accept: 'application/json',
    };
    hooks.apply({ headers: h, query: new URLSearchParams() }, 'held.jwt.t');
    expect(h).toEqual({ accept: 'application/json', Authorization: 'Bearer held.jwt.t' });
    const w: Record<string, string> = { authorization: 'Basic eA==' };
    hooks.applyWs({ headers: w, query: new URLSearchParams() }, null);
    expect(w).toEqual({});
  });

  it('a 401 means the JWT expired, except from change-password (also a missing privilege)', () => {
    expect(hooks.expiry).toBe('forget');
    expect(hooks.isExpired(401, { method: 'GET', path: '/rest/v1/status' })).toBe(true);
    expect(hooks.isExpired(403, { method: 'GET', path: '/rest/v1/status' })).toBe(false);
    expect(hooks.isExpired(401, { method: 'POST', path: '/rest/v1/auth/change-password' })).toBe(false);
    expect(hooks.configured?.({ apiKey: 'k', password: 'p' })).toBeUndefined();
  });

  it('a password change: the new JWT is kept, the answer carries the user and new expiry only', () => {
    const token = jwt(2_100_000_000, 'new');
    const session = answer(200, { loggedIn: true, user: 'office', expiresAt: 1 });
    const x = hooks.exchanged?.(answer(200, { success: 'true', token }), session);
    expect(x?.key).toBe(token);
    expect(JSON.parse(x?.answer.body ?? '')).toEqual({
      success: 'true',
      loggedIn: true,
      user: 'office',
      expiresAt: 2_100_000_000_000,
    });
    const refused = hooks.exchanged?.(answer(400, { code: '102', msg: 'Invalid Password' }), session);
    expect(refused?.key).toBeNull();
    expect(refused?.answer.status).toBe(400);
  });

  it('reads the expiry of a JWT, and nothing from anything else', () => {
    expect(jwtExpiry(jwt(1_700_000_000))).toBe(1_700_000_000_000);
    expect(jwtExpiry('not-a-jwt')).toBeNull();
    expect(jwtExpiry('a.!!!.c')).toBeNull();
    expect(withoutToken('{"TOKEN":"x","jwt":"y","a":1}')).toBe('{"a":1}');
    expect(withoutToken('')).toBe('');
  });
});
