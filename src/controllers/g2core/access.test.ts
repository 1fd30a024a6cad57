import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import type { AccessRequest } from '../../fleet/access';
import {
  canonicalKey,
  g2coreAccess,
  g2coreAccessBodyLimit,
  g2coreAccessNeedsBody,
  isJogOrHomeLine,
  operatorJobLineProblem,
} from './access';
import { jogLines } from './session';

const req = (method: string, path: string, body?: unknown) => ({
  method,
  path,
  query: new URLSearchParams(),
  body: body === undefined ? undefined : JSON.stringify(body),
});

/** The request exactly as the gateway hands it to the policy (its canonical path and query). */
function viaGateway(
  method: string,
  raw: string,
  opts: { body?: string; websocket?: boolean } = {},
): AccessRequest {
  const t = splitTarget(raw);
  if ('error' in t) throw new Error(`${raw}: ${t.error}`);
  return { method, path: t.path, query: t.query, body: opts.body, websocket: opts.websocket };
}

describe('g2core access policy', () => {
  it('reads are for viewers, alarm clear is an audited operator GET', () => {
    expect(g2coreAccess(req('GET', '/status_report'))).toMatchObject({ role: 'viewer', command: false });
    expect(g2coreAccess(req('GET', '/machine/x/vm'))).toMatchObject({ role: 'viewer', command: false });
    expect(g2coreAccess(req('GET', '/machine/clear'))).toMatchObject({ role: 'operator', command: true });
    expect(g2coreAccess(req('GET', '/machine/panic'))).toMatchObject({ role: 'supervisor', command: true });
    for (const p of [
      '/version',
      '/machine',
      '/machine?shallow=true',
      '/machine?filter=%7B%22x%22%3Anull%2C%22y%22%3A%7B%22jm%22%3Anull%7D%7D',
      '/machine/xvm',
      '/machine/x.vm',
      '/machine/sys/ct',
      '/machine/clearance',
      '/status_report?filter=%7B%22posx%22%3A10%2C%22stat%22%3Anull%7D',
      '/operation',
      '/operation/42',
      '/job/3',
    ]) {
      expect(g2coreAccess(viaGateway('GET', p)), p).toMatchObject({ role: 'viewer', command: false });
    }
  });

  it('finding 3: the alarm commands cannot be reached as a viewer read through another spelling', () => {
    const cases: Array<[string, 'operator' | 'supervisor']> = [
      ['/machine/sys/clear', 'operator'],
      ['/machine/sys.clear', 'operator'],
      ['/machine/SYS/CLR', 'operator'],
      ['/machine/Clear', 'operator'],
      ['/machine/clear/', 'operator'],
      ['/machine//clear', 'operator'],
      ['/MACHINE/clear', 'operator'],
      ['/machine/%20clear%20', 'operator'],
      ['/machine/sys%2Fclear', 'operator'],
      ['/machine/sysclear', 'operator'],
      ['/machine/sys/sys/clear', 'operator'],
      ['/machine/sys.panic', 'supervisor'],
      ['/machine/sys/panic', 'supervisor'],
      ['/machine/SYS/ALARM', 'supervisor'],
      ['/machine/sys/shutd', 'supervisor'],
      ['/machine/Sys.Shutd/', 'supervisor'],
      ['/machine/sys%2Ealarm', 'supervisor'],
      ['/machine/%2573ys%252Fpanic', 'supervisor'],
      ['/machine/pan%09ic', 'supervisor'],
    ];
    for (const [p, needs] of cases) {
      for (const method of ['GET', 'HEAD']) {
        const d = g2coreAccess(viaGateway(method, p));
        expect(d, `${method} ${p}`).toMatchObject({ role: needs, command: true });
      }
    }
  });

  it('finding 3: a filter or a GET body that names a command is that command', () => {
    const f = (spec: string) => `?filter=${encodeURIComponent(spec)}`;
    const cases: Array<[string, 'operator' | 'supervisor']> = [
      [`/machine${f('{"clear":null}')}`, 'operator'],
      [`/machine${f('{"sys":{"clr":null}}')}`, 'operator'],
      [`/status_report${f('{"posx":null,"CLEAR":null}')}`, 'operator'],
      [`/machine${f('{"sys.panic":null}')}`, 'supervisor'],
      [`/status_report${f('{"sys":{"alarm":null}}')}`, 'supervisor'],
      [`/machine${f('{"x":null,"y":{"shutd":null}}')}`, 'supervisor'],
      [`/machine${f('{"gc":"G0 X100"}')}`, 'supervisor'],
      // g2core's relaxed JSON ({clear:n}) is not JSON: the gateway cannot see what it names
      [`/machine${f('{panic:n}')}`, 'supervisor'],
      [`/machine${f('')}`, 'supervisor'],
      [`/machine?FILTER=${encodeURIComponent('{"clear":null}')}`, 'operator'],
      [`/machine/xvm${f('{"panic":null}')}`, 'supervisor'],
    ];
    for (const [p, needs] of cases) {
      expect(g2coreAccess(viaGateway('GET', p)), p).toMatchObject({ role: needs, command: true });
    }
    // The design reads GET filters (and even values) from the body: a GET with a body is not a read.
    expect(g2coreAccess(viaGateway('GET', '/machine', { body: '{"panic":null}' })).role).toBe('supervisor');
    expect(g2coreAccess(viaGateway('GET', '/machine/xjm', { body: '1200' })).role).toBe('supervisor');
    expect(g2coreAccess(viaGateway('GET', '/status_report', { body: '' })).role).toBe('viewer');
    expect(g2coreAccessNeedsBody('GET', '/status_report')).toBe('viewer');
    expect(g2coreAccessNeedsBody('HEAD', '/machine/clear')).toBe('viewer');
  });

  it('a WebSocket upgrade (g2core has none; it reaches the server as a GET) is supervisor', () => {
    for (const p of ['/machine/panic', '/machine/clear', '/status_report', '/']) {
      expect(g2coreAccess(viaGateway('GET', p, { websocket: true })).role, p).toBe('supervisor');
    }
  });

  it('settings are supervisor, overrides operator in every key spelling', () => {
    expect(g2coreAccess(req('PUT', '/machine/x/vm', 1))).toMatchObject({ role: 'supervisor', command: true });
    expect(g2coreAccess(req('PUT', '/machine/mfo', 1.2))).toMatchObject({ role: 'operator' });
    for (const p of [
      '/machine/mfo',
      '/machine/sys/mfo',
      '/machine/sys.mfo',
      '/machine/SYS/MFO',
      '/machine/Sso/',
      '/machine/sys%2Fmto',
      '/MACHINE/mfo',
    ]) {
      expect(g2coreAccessNeedsBody('PUT', viaGateway('PUT', p).path), p).toBe(true);
      expect(g2coreAccess(viaGateway('PUT', p, { body: '1.2' })), p).toMatchObject({ role: 'operator' });
    }
    expect(g2coreAccess(viaGateway('PUT', '/machine/mfo', { body: '{"mfo":0.5}' })).role).toBe('operator');
    expect(g2coreAccess(viaGateway('PUT', '/machine/sys/mfo', { body: '{ "sys.mfo" : 1 }' })).role).toBe(
      'operator',
    );
  });

  it('an override whose key or body says more is a supervisor setting', () => {
    for (const [p, body] of [
      ['/machine/mfo', '{"mfo":1.2,"defa":1}'],
      ['/machine/mfo', '{"clear":null}'],
      ['/machine/mfo', '{"xvm":1}'],
      ['/machine/mfo', '{"mfo":1,"mfo":{"defa":1}}'],
      ['/machine/mfo', '{"mfo":{"defa":1}}'],
      ['/machine/mfo', '"1"'],
      ['/machine/mfo', '1.2\n{"gc":"M3"}'],
      ['/machine/mfo', ''],
      ['/machine/mfo', '{mfo:1}'],
      ['/machine/mfo%2F..%2Fxvm', '1'],
      ['/machine/x/mfo', '1'],
      ['/machine/mfox', '1'],
      ['/machine/%256Dfo', '1'],
      ['/machine/xvm', '1'],
      ['/machine', '{"mfo":1}'],
    ] as const) {
      expect(g2coreAccess(viaGateway('PUT', p, { body })), `${p} ${body}`).toMatchObject({
        role: 'supervisor',
        command: true,
      });
    }
    expect(g2coreAccessNeedsBody('PUT', '/machine/xvm')).toBe(false);
  });

  it('canonical keys', () => {
    expect(canonicalKey('sys/MFO')).toBe('mfo');
    expect(canonicalKey('x.vm')).toBe('xvm');
    expect(canonicalKey(' sys . clear ')).toBe('clear');
    expect(canonicalKey('sysmto')).toBe('mto');
  });

  it('classifies POST /operation by its lines', () => {
    expect(g2coreAccessNeedsBody('POST', '/operation')).toBe(true);
    expect(g2coreAccessNeedsBody('POST', '/Operation/')).toBe(true);
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

  it('an operation body with repeated or extra keys (a server may read another copy) is supervisor', () => {
    for (const body of [
      '{"optype":"run","value":["M3 S1000"],"optype":"sendfile"}',
      '{"optype":"sendfile","OPTYPE":"run","value":["M3 S1000"]}',
      '{"optype":"run","value":"M3 S1000","value":["G91 G1 X1"]}',
      '{"optype":"run","value":["G91 G1 X1"],"lines":["M3 S1000"]}',
      '{"optype":"sendfile","value":"3","gcode":"M3 S1000"}',
    ]) {
      expect(g2coreAccess(viaGateway('POST', '/operation', { body })).role, body).toBe('supervisor');
    }
  });

  it('job and operation controls are operator; unknown writes supervisor', () => {
    expect(g2coreAccess(req('PUT', '/operation/42', { opstate: 'kill' }))).toMatchObject({
      role: 'operator',
    });
    expect(g2coreAccess(req('POST', '/job', { name: 'a.nc', gcode: 'G0 X1' }))).toMatchObject({
      role: 'operator',
    });
    // The gateway reads a job's body (a whole job) to classify it.
    expect(g2coreAccessNeedsBody('POST', '/job')).toBe(true);
    expect(g2coreAccessBodyLimit('POST', '/job')).toBeGreaterThan(8 * 1024 * 1024);
    expect(g2coreAccessBodyLimit('POST', '/operation')).toBeUndefined();
    expect(g2coreAccess(req('PUT', '/job/3'))).toMatchObject({ role: 'operator' });
    expect(g2coreAccess(req('DELETE', '/job/3'))).toMatchObject({ role: 'supervisor' });
    expect(g2coreAccess(req('DELETE', '/Job/3/'))).toMatchObject({ role: 'supervisor' });
    // The serial bridge's board reset (^X) is the supervisor's, and says what it is.
    expect(g2coreAccess(req('POST', '/board/reset'))).toMatchObject({
      role: 'supervisor',
      label: expect.stringMatching(/reset the board/),
    });
    expect(g2coreAccess(req('POST', '/firmware'))).toMatchObject({ role: 'supervisor' });
  });
});

describe("g2core: what an operator's job may hold", () => {
  const job = (gcode: string): AccessRequest => ({
    method: 'POST',
    path: '/job',
    query: new URLSearchParams(),
    body: JSON.stringify({ name: 'p.nc', gcode }),
    contentType: 'application/json',
  });

  it("plain G-code is the operator's; settings, JSON and stored-state codes are the supervisor's, the line named", () => {
    const cam = [
      '%',
      '(T1 D=6.35 - flat end mill; 100% feed!)',
      'N10 G90 G94 G17 G21',
      'G54',
      'M6 T1',
      'S12000 M3',
      'G0 X0 Y0',
      'G1 Z-1.5 F300 ; plunge',
      'G2 X10 Y10 I5 J5',
      'g03x0y0r5',
      'G4 P0.5',
      'G38.2 Z-10 F50',
      'M9 M5',
      '',
      'G28',
      'M30',
      '%',
    ].join('\r\n');
    expect(g2coreAccess(job(cam))).toMatchObject({ role: 'operator' });
    for (const [line, why] of [
      ['$defa=1', /settings write/],
      ['$xvm=99999', /settings write/],
      ['{"xsn":0}', /JSON/],
      ['{xvm:null}', /JSON/],
      ['G10 L2 P1 X0', /G10/],
      ['G28.1', /G28\.1/],
      ['G28.3 X0', /G28\.3/],
      ['M100 ({"xvm":1})', /M100/],
      ['M101', /M101/],
      ['M50 P0', /M50/],
      ['?', /control or text-mode/],
      ['!', /control/],
      ['H', /not plain G-code/],
      ['G0 X1 \u0118', /outside printable ASCII/],
      ['G0 X1 E5', /word E/],
      ['G0 X1 (a (nested) comment)', /comment/],
    ] as const) {
      const d = g2coreAccess(job(`G90\nG0 X1\n${line}\nG0 X2`));
      expect(d.role, line).toBe('supervisor');
      expect(d.label, line).toContain(`line 3 ${JSON.stringify(line.trim())}`);
      expect(d.label, line).toMatch(why);
    }
    expect(operatorJobLineProblem('G1 X1')).toBeNull();
    expect(operatorJobLineProblem('G1 X1.5 Y.5 Z-2.')).toBeNull();
    // A long line is refused before any pattern runs on it (no quadratic work on a hostile job).
    expect(operatorJobLineProblem('G1 X' + '1'.repeat(300))).toMatch(/longer than 255/);
    const t0 = performance.now();
    const d = g2coreAccess(job('G1 X' + '1'.repeat(4_000_000) + '!'));
    expect(d.role).toBe('supervisor');
    expect(performance.now() - t0).toBeLessThan(5000); // generous: a quadratic pattern takes hours
  });

  it("a multipart upload is read as its parsers read it; an odd one is the supervisor's", () => {
    const b = '----formdata-undici-0123';
    const part = (name: string, content: string, filename = true): string =>
      `--${b}\r\nContent-Disposition: form-data; name="${name}"${filename ? '; filename="p.nc"' : ''}\r\nContent-Type: application/octet-stream\r\n\r\n${content}\r\n`;
    const up = (body: string, type = `multipart/form-data; boundary=${b}`): AccessRequest => ({
      method: 'POST',
      path: '/job',
      query: new URLSearchParams(),
      body,
      contentType: type,
    });
    const ok = part('file', 'G0 X1\nG1 Y2 F100') + part('name', 'p.nc', false) + `--${b}--\r\n`;
    expect(g2coreAccess(up(ok))).toMatchObject({ role: 'operator' });
    const bad = part('file', 'G0 X1\n$defa=1') + `--${b}--\r\n`;
    expect(g2coreAccess(up(bad)).label).toMatch(/line 2 "\$defa=1" is a settings write/);
    // Two file parts, a preamble, an unknown part or header, another boundary: not classified.
    for (const odd of [
      part('file', 'G0 X1') + part('file', '$defa=1') + `--${b}--`,
      `preamble\r\n${ok}`,
      part('file', 'G0 X1') + part('gcode', '$defa=1') + `--${b}--`,
      part('file', 'G0 X1').replace('Content-Type', 'X-Other') + `--${b}--`,
      part('file', 'G0 X1'),
    ])
      expect(g2coreAccess(up(odd)).role).toBe('supervisor');
    expect(g2coreAccess(up(ok, `multipart/form-data; boundary=other`)).role).toBe('supervisor');
    expect(g2coreAccess(up(ok, `multipart/form-data; boundary=${b}; charset=x`)).role).toBe('supervisor');
    // JSON with other keys, a repeated key, or no gcode: not classified.
    for (const body of [
      '{"name":"a","gcode":"G0 X1","file":"$defa=1"}',
      '{"gcode":"$defa=1","gcode":"G0 X1"}',
      '{"name":"a"}',
      'G0 X1',
    ])
      expect(g2coreAccess({ ...job(''), body }).role, body).toBe('supervisor');
  });
});
