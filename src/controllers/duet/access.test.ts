import { describe, expect, it } from 'vitest';
import { classifyCode, codeWords, duetAccess, duetAccessNeedsBody } from './access';

const req = (method: string, path: string, body?: string) => ({
  method,
  path,
  query: new URLSearchParams(),
  body,
});

describe('duet access policy', () => {
  it('reads are viewer and not commands', () => {
    for (const p of [
      '/machine/status',
      '/machine/noop',
      '/machine/connect',
      '/machine/directory/0%3A%2Fgcodes',
      '/machine/fileinfo/x',
    ]) {
      expect(duetAccess(req('GET', p))).toMatchObject({ role: 'viewer', command: false });
    }
    expect(duetAccess({ ...req('GET', '/machine'), websocket: true }).role).toBe('viewer');
  });

  it('classifies G-code bodies', () => {
    expect(classifyCode('M25').role).toBe('operator');
    expect(classifyCode('M24\n').role).toBe('operator');
    expect(classifyCode('M0 ; cancel').role).toBe('operator');
    expect(classifyCode('M32 "0:/gcodes/part.gcode"').role).toBe('operator');
    expect(classifyCode('M292 P0 S12 R{5}').role).toBe('operator');
    expect(classifyCode('M112\nM999').role).toBe('operator');
    expect(classifyCode('M999').role).toBe('supervisor');
    expect(classifyCode('M999\nM112').role).toBe('supervisor');
    expect(classifyCode('G28').role).toBe('supervisor');
    expect(classifyCode('M25\nG1 X10').role).toBe('supervisor');
    expect(classifyCode('M98 P"0:/macros/home"').role).toBe('supervisor');
    expect(classifyCode('M562 P1').role).toBe('supervisor');
    expect(classifyCode('echo "M25"').role).toBe('supervisor');
    expect(classifyCode('').role).toBe('supervisor');
    // a quoted path that looks like a code does not count
    expect(classifyCode('M32 "0:/gcodes/G28 M999.gcode"').role).toBe('operator');
    expect(classifyCode('M00').role).toBe('operator');
    expect(codeWords('N10 M25 ; x').map((w) => w.word)).toEqual(['M25']);
    const d = duetAccess(req('POST', '/machine/code', 'M25'));
    expect(d).toMatchObject({ role: 'operator', command: true });
    expect(duetAccessNeedsBody('POST', '/machine/code')).toBe(true);
    expect(duetAccessNeedsBody('PUT', '/machine/file/x')).toBe(false);
  });

  it('system files (passwords in config.g) are read by supervisors only, height maps by anyone', () => {
    const get = (p: string) => duetAccess(req('GET', `/machine/file/${encodeURIComponent(p)}`));
    expect(get('0:/sys/config.g')).toMatchObject({ role: 'supervisor', command: false });
    expect(get('0:/gcodes/../sys/config.g').role).toBe('supervisor');
    expect(get('0:/sys/heightmap.csv').role).toBe('viewer');
    expect(get('0:/gcodes/a.gcode').role).toBe('viewer');
    expect(get('0:/macros/Park head.g').role).toBe('viewer');
  });

  it('uploads into gcodes are operator, elsewhere supervisor', () => {
    expect(duetAccess(req('PUT', `/machine/file/${encodeURIComponent('0:/gcodes/a.gcode')}`)).role).toBe(
      'operator',
    );
    expect(duetAccess(req('PUT', `/machine/file/${encodeURIComponent('0:/sys/config.g')}`)).role).toBe(
      'supervisor',
    );
    expect(
      duetAccess(req('PUT', `/machine/file/${encodeURIComponent('0:/gcodes/../sys/config.g')}`)).role,
    ).toBe('supervisor');
  });

  it('files, folders and plugins changes are supervisor commands', () => {
    for (const [m, p] of [
      ['DELETE', '/machine/file/x'],
      ['POST', '/machine/file/move'],
      ['PUT', '/machine/directory/x'],
      ['PUT', '/machine/plugin'],
      ['DELETE', '/machine/plugin'],
      ['POST', '/machine/startPlugin'],
      ['POST', '/machine/stopPlugin'],
      ['POST', '/machine/somethingNew'],
    ] as const) {
      expect(duetAccess(req(m, p))).toMatchObject({ role: 'supervisor', command: true });
    }
  });
});
