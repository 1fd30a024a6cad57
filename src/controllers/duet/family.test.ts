import { describe, expect, it } from 'vitest';
import { duetFamily } from './family';

describe('duetFamily', () => {
  const inject = duetFamily.gateway!.injectSecrets!;
  const req = (path: string, q = '') => ({ method: 'GET', path, headers: {}, query: new URLSearchParams(q) });

  it('puts the configured password into GET /machine/connect, replacing the browser value', () => {
    const r = req('/machine/connect', 'password=typed');
    inject(r, { password: 's3cret' });
    expect(r.query.get('password')).toBe('s3cret');
    expect(r.query.getAll('password')).toHaveLength(1);
  });

  it('leaves other requests and machines without a password alone', () => {
    const other = req('/machine/status');
    inject(other, { password: 's3cret' });
    expect(other.query.has('password')).toBe(false);
    const typed = req('/machine/connect', 'password=typed');
    inject(typed, {});
    expect(typed.query.get('password')).toBe('typed');
  });

  it('is Node-safe and makes a duet simulator', () => {
    const sim = duetFamily.createSimulator({ id: 'x', name: 'x' });
    expect(sim.kind).toBe('duet');
    expect(sim.controls?.().map((c) => c.id)).toContain('box-7');
    sim.dispose();
    expect(duetFamily.accessNeedsBody?.('POST', '/machine/code')).toBe(true);
  });
});
