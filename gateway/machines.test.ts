import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import {
  DEMO_FLEET,
  loadMachines,
  MachinesFileError,
  machineInfo,
  normalizeFingerprint,
  secretForms,
  redact,
} from './machines';
import { tempDir, writeJson } from './test-util';

const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0)) c();
});

function dir(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return t.dir;
}

function problemsOf(machines: unknown[], env: NodeJS.ProcessEnv = {}): { file: string; message: string } {
  const d = dir();
  const file = writeJson(path.join(d, 'm.json'), { machines });
  try {
    loadMachines({ machinesFile: file, env, cwd: d });
  } catch (e) {
    expect(e).toBeInstanceOf(MachinesFileError);
    return { file, message: (e as Error).message };
  }
  throw new Error('the file was accepted');
}

const good = { id: 'laser-1', name: 'Laser 1', kind: 'xtool', url: 'http://10.0.0.50:8080' };

describe('machines file', () => {
  it('loads the documented example, resolving env: secrets', () => {
    const d = dir();
    const file = writeJson(path.join(d, 'machines.json'), {
      machines: [
        {
          id: 'plasma-1',
          name: 'Plasma table',
          kind: 'touchcut',
          url: 'https://kineticcutter',
          apiKey: 'env:TOUCHCUT_KEY',
        },
        { id: 'router', name: 'Router', kind: 'g2core', url: 'http://10.0.0.12:8080' },
        {
          id: 'mk3',
          name: 'Printer A',
          kind: 'duet',
          url: 'http://duet3.local',
          password: 'env:DUET_PASSWORD',
        },
        {
          id: 'laser-1',
          name: 'Laser 1',
          kind: 'xtool',
          url: 'http://10.0.0.50:8080',
          wsUrl: 'ws://10.0.0.50:8081',
        },
        { id: 'p1', name: 'Prunt 1', kind: 'prunt', url: 'http://prunt.local:8080' },
        { id: 'demo-laser', name: 'Demo laser', kind: 'xtool', simulated: true },
      ],
    });
    // machines.json in the project root is picked up without SHOPDECK_MACHINES.
    const c = loadMachines({ env: { TOUCHCUT_KEY: 'k-123456', DUET_PASSWORD: 'reprap' }, cwd: d });
    expect(c.file).toBe(file);
    expect(c.machines.map((m) => m.id)).toEqual(['plasma-1', 'router', 'mk3', 'laser-1', 'p1', 'demo-laser']);
    expect(c.machines[0]?.secrets).toEqual({ apiKey: 'k-123456' });
    expect(c.machines[2]?.secrets).toEqual({ password: 'reprap' });
    expect(c.machines[3]?.wsUrl?.href).toBe('ws://10.0.0.50:8081/');
    expect(c.machines[5]).toMatchObject({ simulated: true, url: null });
  });

  it('uses the built-in demo fleet when there is no file', () => {
    const c = loadMachines({ env: {}, cwd: dir() });
    expect(c.file).toBeNull();
    expect(c.machines.map((m) => [m.id, m.kind, m.simulated])).toEqual(
      DEMO_FLEET.map((m) => [m.id, m.kind, true]),
    );
    expect(c.machines.map((m) => m.id)).toEqual([
      'demo-xtool',
      'demo-touchcut',
      'demo-duet',
      'demo-duet-standalone',
      'demo-prunt',
      'demo-g2core',
    ]);
  });

  it('SHOPDECK_MACHINES wins and must exist', () => {
    const d = dir();
    writeJson(path.join(d, 'machines.json'), { machines: [good] });
    const other = writeJson(path.join(d, 'other.json'), { machines: [{ ...good, id: 'other' }] });
    expect(loadMachines({ env: { SHOPDECK_MACHINES: 'other.json' }, cwd: d }).machines[0]?.id).toBe('other');
    expect(other).toContain('other.json');
    expect(() => loadMachines({ env: { SHOPDECK_MACHINES: 'nope.json' }, cwd: d })).toThrow(
      /nope\.json.*does not exist/s,
    );
  });

  it('names the file, the entry and the field: unknown kind', () => {
    const { file, message } = problemsOf([good, { ...good, id: 'cutter', kind: 'plasmatron' }]);
    expect(message).toContain(file);
    expect(message).toMatch(
      /machines\[1\] \(id "cutter"\): field "kind": must be one of xtool, touchcut, duet, prunt, g2core/,
    );
  });

  it('bad id', () => {
    expect(problemsOf([{ ...good, id: 'Laser 1' }]).message).toMatch(
      /machines\[0\] \(id "Laser 1"\): field "id": must be 1 to 40/,
    );
  });

  it('duplicate id', () => {
    expect(problemsOf([good, good]).message).toMatch(
      /machines\[1\] \(id "laser-1"\): field "id": duplicate id "laser-1" \(also machines\[0\]\)/,
    );
  });

  it('missing url unless simulated', () => {
    const { message } = problemsOf([{ id: 'a', name: 'A', kind: 'duet' }]);
    expect(message).toMatch(
      /machines\[0\] \(id "a"\): field "url": missing \(required unless "simulated": true\)/,
    );
  });

  it('env:NAME not set', () => {
    const { message } = problemsOf([{ ...good, kind: 'touchcut', apiKey: 'env:TOUCHCUT_KEY' }]);
    expect(message).toMatch(
      /machines\[0\] \(id "laser-1"\): field "apiKey": environment variable TOUCHCUT_KEY is not set/,
    );
  });

  it('bad url, bad wsUrl, unknown field, broken JSON', () => {
    expect(problemsOf([{ ...good, url: 'ftp://x' }]).message).toMatch(
      /field "url": "ftp:\/\/x" must start with http:\/\/ or https:\/\//,
    );
    expect(problemsOf([{ ...good, url: 'not a url' }]).message).toMatch(
      /field "url": "not a url" is not a URL/,
    );
    expect(problemsOf([{ ...good, wsUrl: 'http://x:8081' }]).message).toMatch(/field "wsUrl"/);
    expect(problemsOf([{ ...good, wsurl: 'ws://x' }]).message).toMatch(
      /machines\[0\] \(id "laser-1"\): field "wsurl": unknown field/,
    );
    const d = dir();
    const f = path.join(d, 'broken.json');
    writeJson(f, {});
    expect(() => loadMachines({ machinesFile: f, env: {}, cwd: d })).toThrow(
      /broken\.json[\s\S]*field "machines": missing/,
    );
  });
});

describe('api (duet: dsf or standalone)', () => {
  it('is optional, only dsf or standalone, only for a duet, and not sent to the browser', () => {
    const d = dir();
    const duet = { id: 'p1', name: 'P1', kind: 'duet', url: 'http://10.0.0.9' };
    const file = writeJson(path.join(d, 'm.json'), {
      machines: [
        { ...duet, api: 'standalone' },
        { ...duet, id: 'p2', api: 'dsf' },
        { ...duet, id: 'p3' },
      ],
    });
    const [a, b, c] = loadMachines({ machinesFile: file, env: {}, cwd: d }).machines;
    expect([a?.api, b?.api, c && 'api' in c]).toEqual(['standalone', 'dsf', false]);
    expect(a && 'api' in machineInfo(a)).toBe(false);
    expect(problemsOf([{ ...duet, api: 'rrf' }]).message).toMatch(
      /machines\[0\] \(id "p1"\): field "api": must be one of dsf, standalone/,
    );
    expect(problemsOf([{ ...good, api: 'standalone' }]).message).toMatch(
      /machines\[0\] \(id "laser-1"\): field "api": only for "kind": "duet"/,
    );
  });
});

describe('group', () => {
  function load(machines: unknown[]) {
    const d = dir();
    const file = writeJson(path.join(d, 'm.json'), { machines });
    return loadMachines({ machinesFile: file, env: {}, cwd: d }).machines;
  }

  it('is optional, trimmed, and reaches the browser in the machine info', () => {
    const [a, b] = load([
      { ...good, group: '  Bay 2 — lasers ' },
      { ...good, id: 'laser-2' },
    ]);
    expect(a?.group).toBe('Bay 2 — lasers');
    expect(b && 'group' in b).toBe(false);
    expect(a && machineInfo(a)).toEqual({
      id: 'laser-1',
      name: 'Laser 1',
      kind: 'xtool',
      simulated: false,
      group: 'Bay 2 — lasers',
    });
    // An old file (no group) gives the same info as before: no group key at all.
    expect(b && machineInfo(b)).toEqual({ id: 'laser-2', name: 'Laser 1', kind: 'xtool', simulated: false });
  });

  it('accepts 60 characters, refuses 61, empty, blank, non-strings and control characters', () => {
    expect(load([{ ...good, group: 'x'.repeat(60) }])[0]?.group).toHaveLength(60);
    const cases: Array<[unknown, RegExp]> = [
      ['x'.repeat(61), /field "group": too long \(at most 60 characters\)/],
      ['', /field "group": must not be empty/],
      ['   ', /field "group": must not be empty/],
      [7, /field "group": must be a string/],
      [null, /field "group": must be a string/],
      ['Bay\n2', /field "group": must be printable text/],
      ['Bay\u0007', /field "group": must be printable text/],
      ['Bay\u200b2', /field "group": must be printable text/],
      ['Bay\u20282', /field "group": must be printable text/],
    ];
    for (const [group, expected] of cases) {
      const { file, message } = problemsOf([{ ...good, group }]);
      expect(message).toContain(file);
      expect(message).toMatch(/machines\[0\] \(id "laser-1"\)/);
      expect(message).toMatch(expected);
    }
  });
});

describe('tlsFingerprint', () => {
  const FP =
    'A1:B2:C3:D4:E5:F6:07:18:29:3A:4B:5C:6D:7E:8F:90:A1:B2:C3:D4:E5:F6:07:18:29:3A:4B:5C:6D:7E:8F:90';
  const cutter = { id: 'plasma-1', name: 'Plasma table', kind: 'touchcut', url: 'https://kineticcutter' };

  function load(machines: unknown[]) {
    const d = dir();
    const file = writeJson(path.join(d, 'm.json'), { machines });
    return loadMachines({ machinesFile: file, env: {}, cwd: d }).machines;
  }

  it('is stored as uppercase colon pairs, whatever form the file uses', () => {
    const ms = load([
      { ...cutter, tlsFingerprint: FP },
      { ...cutter, id: 'p2', tlsFingerprint: FP.toLowerCase() },
      { ...cutter, id: 'p3', tlsFingerprint: FP.replace(/:/g, '') },
      { ...cutter, id: 'p4', tlsFingerprint: ` ${FP.replace(/:/g, '').toLowerCase()} ` },
      { ...cutter, id: 'p5' },
      // Only the socket is TLS: the fingerprint applies to it.
      { ...good, id: 'l2', wsUrl: 'wss://10.0.0.50:8081', tlsFingerprint: FP },
    ]);
    expect(ms.map((m) => m.tlsFingerprint)).toEqual([FP, FP, FP, FP, undefined, FP]);
    expect('tlsFingerprint' in ms[4]!).toBe(false);
    expect(normalizeFingerprint(FP.toLowerCase())).toBe(FP);
  });

  it('names the file, the entry and the field when it is not a SHA-256 fingerprint', () => {
    for (const bad of [
      FP.slice(0, -3), // 31 pairs
      FP.replace(/:/g, '').slice(1), // 63 digits
      FP.replace('A1', 'G1'),
      FP.replace(/:/g, ' '),
      'sha256 Fingerprint=' + FP,
      '',
    ]) {
      const { file, message } = problemsOf([{ ...cutter, tlsFingerprint: bad }]);
      expect(message, bad).toContain(file);
      expect(message, bad).toMatch(
        /machines\[0\] \(id "plasma-1"\): field "tlsFingerprint": must be the SHA-256 fingerprint of the controller's certificate, 64 hex digits with or without colons/,
      );
    }
    expect(problemsOf([{ ...cutter, tlsFingerprint: 42 }]).message).toMatch(
      /machines\[0\] \(id "plasma-1"\): field "tlsFingerprint": must be a string/,
    );
  });

  it('is refused on a machine without an https:// or wss:// address', () => {
    for (const m of [
      { ...good, tlsFingerprint: FP },
      { ...good, wsUrl: 'ws://10.0.0.50:8081', tlsFingerprint: FP },
      { id: 'sim', name: 'Sim', kind: 'touchcut', simulated: true, tlsFingerprint: FP },
    ]) {
      expect(problemsOf([m]).message).toMatch(
        new RegExp(
          `machines\\[0\\] \\(id "${m.id}"\\): field "tlsFingerprint": only used for https:// and wss:// addresses, and this machine has none`,
        ),
      );
    }
    // A url that is wrong anyway gets one message, not a second one about TLS.
    const { message } = problemsOf([{ ...good, url: 'ftp://x', tlsFingerprint: FP }]);
    expect(message).toMatch(/field "url"/);
    expect(message).not.toMatch(/tlsFingerprint/);
  });
});

describe('secret redaction', () => {
  it('covers the forms a controller could echo a secret in', () => {
    const forms = secretForms({ apiKey: 'a/b c"d', password: 'xy' });
    const text = `${'a/b c"d'} ${encodeURIComponent('a/b c"d')} ${JSON.stringify('a/b c"d')} ${Buffer.from('a/b c"d').toString('base64')}`;
    expect(redact(text, forms)).not.toMatch(/a\/b|a%2Fb|YS9i/);
    // Secrets shorter than 4 characters are not hunted in bodies (they would mangle every answer).
    expect(forms).not.toContain('xy');
  });

  describe('serial g2core boards (issue 19)', () => {
    const board = { id: 'mill', name: 'Mill', kind: 'g2core' };

    function load(machines: unknown[]) {
      const d = dir();
      return loadMachines({ machinesFile: writeJson(path.join(d, 'm.json'), { machines }), env: {}, cwd: d });
    }

    it('accepts "serial" instead of "url", with baudRate defaulting to 115200', () => {
      const c = load([
        { ...board, serial: '/dev/ttyACM0' },
        { ...board, id: 'mill-2', serial: 'auto', baudRate: 230400 },
        { ...board, id: 'mill-3', serial: 'COM3' },
      ]);
      expect(c.machines.map((m) => [m.url, m.simulated, m.serial])).toEqual([
        [null, false, { path: '/dev/ttyACM0', baudRate: 115200 }],
        [null, false, { path: 'auto', baudRate: 230400 }],
        [null, false, { path: 'COM3', baudRate: 115200 }],
      ]);
      // The browser learns nothing about the port.
      expect(machineInfo(c.machines[0]!)).not.toHaveProperty('serial');
    });

    it('names the file, the entry and the field for each wrong serial entry', () => {
      const { file, message } = problemsOf([
        { ...board, serial: '/dev/ttyACM0', url: 'http://10.0.0.9' },
        { ...board, id: 'b', kind: 'duet', serial: '/dev/ttyACM1' },
        { ...board, id: 'c', serial: 'ttyACM0' },
        { ...board, id: 'd', serial: '/dev/../etc/passwd' },
        { ...board, id: 'e', serial: '/dev/ttyACM0', baudRate: 'fast' },
        { ...board, id: 'f', url: 'http://10.0.0.9', baudRate: 115200 },
        { ...board, id: 'g', serial: '/dev/ttyACM0', simulated: true },
        { ...board, id: 'h' },
      ]);
      expect(message).toContain(file);
      expect(message).toContain(
        'machines[0] (id "mill"): field "serial": use either "url" or "serial", not both',
      );
      expect(message).toContain('machines[1] (id "b"): field "serial": only g2core boards');
      expect(message).toContain('machines[2] (id "c"): field "serial": "ttyACM0" must be a device');
      expect(message).toContain('machines[3] (id "d"): field "serial"');
      expect(message).toContain('machines[4] (id "e"): field "baudRate": must be a number');
      expect(message).toContain('machines[5] (id "f"): field "baudRate": only used with "serial"');
      expect(message).toContain('machines[6] (id "g"): field "serial": a simulated machine has no port');
      expect(message).toContain(
        'machines[7] (id "h"): field "url": missing (required unless "simulated": true, or "serial"',
      );
    });
  });
});
