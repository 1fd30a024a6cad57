import { describe, expect, it } from 'vitest';
import { g2coreAccess, g2coreAccessNeedsBody, isJogOrHomeLine } from './access';
import { jogLines } from './session';

const req = (method: string, path: string, body?: unknown) => ({
  method,
  path,
  query: new URLSearchParams(),
  body: body === undefined ? undefined : JSON.stringify(body),
});

describe('g2core access policy', () => {
  it('reads are for viewers, alarm clear is an audited operator GET', () => {
    expect(g2coreAccess(req('GET', '/status_report'))).toMatchObject({ role: 'viewer', command: false });
    expect(g2coreAccess(req('GET', '/machine/x/vm'))).toMatchObject({ role: 'viewer', command: false });
    expect(g2coreAccess(req('GET', '/machine/clear'))).toMatchObject({ role: 'operator', command: true });
    expect(g2coreAccess(req('GET', '/machine/panic'))).toMatchObject({ role: 'supervisor', command: true });
  });

  it('settings are supervisor, overrides operator', () => {
    expect(g2coreAccess(req('PUT', '/machine/x/vm', 1))).toMatchObject({ role: 'supervisor', command: true });
    expect(g2coreAccess(req('PUT', '/machine/mfo', 1.2))).toMatchObject({ role: 'operator' });
  });

  it('classifies POST /operation by its lines', () => {
    expect(g2coreAccessNeedsBody('POST', '/operation')).toBe(true);
    expect(g2coreAccessNeedsBody('GET', '/operation')).toBe(false);
    const jog = jogLines({ axis: 'x', distance: -10, feed: 1000 });
    expect(g2coreAccess(req('POST', '/operation', { optype: 'run', value: jog }))).toMatchObject({
      role: 'operator',
    });
    expect(g2coreAccess(req('POST', '/operation', { optype: 'run', value: 'G28.2 X0 Y0\n' }))).toMatchObject({
      role: 'operator',
      label: 'home axes',
    });
    expect(g2coreAccess(req('POST', '/operation', { optype: 'run', value: ['G0 X10'] }))).toMatchObject({
      role: 'supervisor',
    });
    expect(
      g2coreAccess(req('POST', '/operation', { optype: 'run', value: [...jog, 'M3 S1000'] })),
    ).toMatchObject({
      role: 'supervisor',
    });
    expect(g2coreAccess(req('POST', '/operation'))).toMatchObject({ role: 'supervisor' });
    expect(g2coreAccess(req('POST', '/operation', { optype: 'sendfile', value: '3' }))).toMatchObject({
      role: 'operator',
    });
    expect(isJogOrHomeLine('G91 G1 X1; G0 X100')).toBe(false);
  });

  it('job and operation controls are operator; unknown writes supervisor', () => {
    expect(g2coreAccess(req('PUT', '/operation/42', { opstate: 'kill' }))).toMatchObject({
      role: 'operator',
    });
    expect(g2coreAccess(req('POST', '/job'))).toMatchObject({ role: 'operator' });
    expect(g2coreAccess(req('PUT', '/job/3'))).toMatchObject({ role: 'operator' });
    expect(g2coreAccess(req('DELETE', '/job/3'))).toMatchObject({ role: 'supervisor' });
    expect(g2coreAccess(req('POST', '/firmware'))).toMatchObject({ role: 'supervisor' });
  });
});
