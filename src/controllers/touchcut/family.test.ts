import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import { touchcutAccess } from './access';
import { touchcutGateway } from './family';

const KEY = 'K-secret';

/** Runs the family's `injectSecrets` on a request as the gateway forwards it; returns the headers. */
function forwarded(
  method: string,
  raw: string,
  headers: Record<string, string> = {},
): Record<string, string> {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  const h = { ...headers };
  touchcutGateway.injectSecrets?.({ method, path: t.path, headers: h, query: t.query }, { apiKey: KEY });
  return h;
}

const hasKey = (h: Record<string, string>) =>
  Object.entries(h).some(([k, v]) => k.toLowerCase() === 'x-touchcut-api-key' && v === KEY);

describe('finding 4: the TouchCut API key goes only on GETs of the documented reads', () => {
  it('adds it to the documented reads, however the path is spelt', () => {
    for (const p of [
      '/rest/v1/status',
      '/rest/v1/status?units=metric',
      '/rest/v1/stats?start-date=2024-01-01',
      '/rest/v1/monitor',
      '/rest/v1/programs?offset=0&limit=20',
      '/rest/v1/unloader',
      '/rest/v1/screenshot',
      '/REST/V1/Status/',
      '//rest//v1//monitor',
    ]) {
      expect(hasKey(forwarded('GET', p)), p).toBe(true);
    }
  });

  it('never adds it to other methods or undocumented paths', () => {
    for (const [m, p] of [
      ['POST', '/rest/v1/status'],
      ['PUT', '/rest/v1/status'],
      ['DELETE', '/rest/v1/programs'],
      ['PATCH', '/rest/v1/unloader'],
      ['HEAD', '/rest/v1/status'],
      ['OPTIONS', '/rest/v1/status'],
      ['POST', '/rest/v1/unloader/move'],
      ['POST', '/rest/v1/settings'],
      ['POST', '/rest/v1/auth/change-password'],
      ['GET', '/rest/v1/auth/change-password'],
      ['GET', '/rest/v1/auth'],
      ['GET', '/rest/v1/machine-info'],
      ['GET', '/rest/v1/unloader/move'],
      ['GET', '/rest/v1/status/extra'],
      ['GET', '/rest/v1/status%2F..%2Fsettings'],
      ['GET', '/rest/v1/settings'],
      ['GET', '/rest/v2/status'],
      ['GET', '/rest/v1'],
      ['GET', '/'],
      ['GET', '/index.html'],
      ['GET', '/status'],
    ] as const) {
      expect(hasKey(forwarded(m, p)), `${m} ${p}`).toBe(false);
    }
  });

  it('drops a key the browser sent, whatever the request', () => {
    for (const [m, p] of [
      ['GET', '/rest/v1/status'],
      ['POST', '/rest/v1/settings'],
      ['GET', '/rest/v1/undocumented'],
    ] as const) {
      const h = forwarded(m, p, { 'x-touchcut-api-key': 'from-browser', 'X-TOUCHCUT-API-KEY': 'again' });
      expect(Object.values(h), `${m} ${p}`).not.toContain('from-browser');
      expect(Object.values(h), `${m} ${p}`).not.toContain('again');
    }
  });

  it('the gateway’s held login (Bearer) is used instead of the key', () => {
    expect(forwarded('GET', '/rest/v1/status', { authorization: 'Bearer a.b.c' })).toEqual({
      authorization: 'Bearer a.b.c',
    });
  });

  it('a Bearer the browser forged is dropped first (held session), so the key is still added', () => {
    const t = splitTarget('/rest/v1/status');
    if ('error' in t) throw new Error(t.error);
    const h: Record<string, string> = { Authorization: 'Bearer forged', cookie: '__Secure-jwt=forged' };
    touchcutGateway.session?.apply({ headers: h, query: t.query }, null);
    touchcutGateway.injectSecrets?.(
      { method: 'GET', path: t.path, headers: h, query: t.query },
      { apiKey: KEY },
    );
    expect(h).toEqual({ 'X-TouchCut-API-Key': KEY });
  });

  it('every request that gets the key is a viewer read of the access rule (the two agree)', () => {
    const paths = ['/rest/v1/status', '/REST/V1/SCREENSHOT/', '/rest/v1/undocumented', '/rest/v1/status/x'];
    let keyed = 0;
    for (const p of paths) {
      const t = splitTarget(p);
      if ('error' in t) throw new Error(t.error);
      const d = touchcutAccess({ method: 'GET', path: t.path, query: t.query });
      if (hasKey(forwarded('GET', p))) {
        keyed++;
        expect(d, p).toMatchObject({ role: 'viewer', command: false });
      } else {
        expect(d.role, p).toBe('supervisor');
      }
    }
    expect(keyed).toBe(2);
  });
});
