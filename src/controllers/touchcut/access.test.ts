import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import type { AccessRequest } from '../../fleet/access';
import { takesApiKey, touchcutAccess, touchcutResource } from './access';

function viaGateway(method: string, raw: string, websocket?: boolean): AccessRequest {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { method, path: t.path, query: t.query, websocket };
}

describe('touchcut access policy', () => {
  it('documented reads are viewer reads in every spelling (case, trailing slash, HEAD)', () => {
    for (const p of [
      '/rest/v1/status?units=metric',
      '/REST/V1/STATUS',
      '/rest/v1/Status/',
      '/rest/v1/stats',
      '/rest/v1/monitor?fields=axes.*',
      '/rest/v1/programs',
      '/rest/v1/unloader',
      '/rest/v1/screenshot',
      '/rest/v1/machine-info',
    ]) {
      for (const m of ['GET', 'HEAD']) {
        expect(touchcutAccess(viaGateway(m, p)), `${m} ${p}`).toMatchObject({
          role: 'viewer',
          command: false,
        });
      }
    }
  });

  it('the auth requests in any spelling keep their roles', () => {
    // The login is the machine's, shared by every viewer: logging it in or out is an operator's
    // audited command; which user is logged in is a viewer read.
    expect(touchcutAccess(viaGateway('POST', '/rest/v1/auth'))).toMatchObject({
      role: 'operator',
      command: true,
    });
    expect(touchcutAccess(viaGateway('POST', '/REST/v1/Auth/')).role).toBe('operator');
    expect(touchcutAccess(viaGateway('DELETE', '/rest/v1/auth'))).toMatchObject({
      role: 'operator',
      command: true,
    });
    for (const m of ['GET', 'HEAD'])
      expect(touchcutAccess(viaGateway(m, '/rest/v1/Auth/')), m).toMatchObject({
        role: 'viewer',
        command: false,
      });
    expect(touchcutAccess(viaGateway('PUT', '/rest/v1/auth')).role).toBe('supervisor');
    expect(touchcutAccess(viaGateway('POST', '/rest/v1/auth/change-password'))).toMatchObject({
      role: 'operator',
      command: true,
    });
    expect(touchcutAccess(viaGateway('POST', '/rest/v1/AUTH/Change-Password/')).role).toBe('operator');
  });

  it('undocumented requests and WebSocket upgrades need a supervisor (a GET there may be a command)', () => {
    for (const p of [
      '/rest/v1/unloader/move',
      '/rest/v1/status/extra',
      '/rest/v1/status%2F..%2Fsettings',
      '/rest/v2/status',
      '/',
      '/index.html',
      '/rest/v1/auth/change-password',
    ]) {
      expect(touchcutAccess(viaGateway('GET', p)), p).toMatchObject({ role: 'supervisor', command: true });
    }
    for (const [m, p] of [
      ['POST', '/rest/v1/settings'],
      ['PUT', '/rest/v1/status'],
      ['DELETE', '/rest/v1/programs'],
      ['POST', '/rest/v1/unloader'],
    ] as const) {
      expect(touchcutAccess(viaGateway(m, p)).role, `${m} ${p}`).toBe('supervisor');
    }
    expect(touchcutAccess(viaGateway('GET', '/rest/v1/status', true)).role).toBe('supervisor');
  });

  it('the key-taking reads and the resource names', () => {
    expect(touchcutResource('/REST/V1/Status/')).toBe('status');
    expect(touchcutResource('rest/v1/auth/change-password')).toBe('auth/change-password');
    expect(touchcutResource('/rest/v2/status')).toBeNull();
    expect(takesApiKey('GET', '/rest/v1/screenshot')).toBe(true);
    expect(takesApiKey('get', '/rest/v1/status')).toBe(true);
    expect(takesApiKey('HEAD', '/rest/v1/status')).toBe(false);
    expect(takesApiKey('GET', '/rest/v1/machine-info')).toBe(false);
  });
});
