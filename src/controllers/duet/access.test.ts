import { describe, expect, it } from 'vitest';
import { splitTarget } from '../../../gateway/paths';
import type { AccessRequest } from '../../fleet/access';
import {
  classifyCode,
  duetAccess,
  duetAccessNeedsBody,
  isJobFile,
  normaliseDuetPath,
  openToViewers,
  tokenizeGcode,
} from './access';

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

const role = (method: string, raw: string, body?: string) =>
  duetAccess(viaGateway(method, raw, { body })).role;

describe('duet access policy', () => {
  it("reads the console's own features need are viewer reads and not commands", () => {
    for (const p of [
      '/machine/status',
      '/machine/model',
      '/machine/noop',
      '/machine/connect?password=x',
      '/machine/disconnect',
      '/machine/directory/0%3A%2Fgcodes',
      '/machine/directory/0%3A%2Fsys',
      '/machine/directory/0%3A%2Fmacros',
      '/machine/fileinfo/0%3A%2Fgcodes%2Fpart.gcode?readThumbnailContent=true',
      '/machine/file/0%3A%2Fgcodes%2Fsub%2Fa%20b.gcode',
      '/machine/file/0%3A%2Fsys%2Fheightmap.csv',
    ]) {
      expect(duetAccess(viaGateway('GET', p)), p).toMatchObject({ role: 'viewer', command: false });
    }
    expect(duetAccess(viaGateway('GET', '/machine?sessionKey=k', { websocket: true }))).toMatchObject({
      role: 'viewer',
    });
  });

  it('finding 1: config.g in every spelling DSF resolves to it needs a supervisor (GET and HEAD)', () => {
    const spellings = [
      '/machine/file/0%3A%2Fsys%2Fconfig.g',
      '/machine/file/sys/config.g',
      '/machine/file/sys%2Fconfig.g',
      '/machine/file/0:%5Csys%5Cconfig.g',
      '/machine/file/%5Csys%5Cconfig.g',
      '/machine/file/%2Fsys%2Fconfig.g',
      '/machine/file/0:sys/config.g',
      '/machine/file/0%3Asys%2Fconfig.g',
      '/machine/file/00:/sys/config.g',
      '/machine/file/0:/SYS/CONFIG.G',
      '/machine/file/0%3A%2FSys%2Fconfig.g',
      '/machine/file/0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g',
      '/machine/file/0:/gcodes%2F..%2Fsys%2Fconfig.g',
      '/machine/file/0:/gcodes/..%5Csys%5Cconfig.g',
      '/machine/file/0%3A%2F.%2Fsys%2Fconfig.g',
      '/machine/file/0:/gcodes/sub/..%2F..%2Fsys/config.g',
      '/machine/file/1:/sys/config.g',
      '/machine/file/1%3A%2Fgcodes%2Fx.gcode',
      '/Machine/File/0:/sys/config.g',
      '/MACHINE/FILE/0%3A%2Fsys%2Fconfig.g',
      '/machine/file/0:/sys/config.g/',
      // DSF decodes the route value a second time (HttpUtility.UrlDecode: %XX, %uXXXX and +).
      '/machine/file/0:%252Fsys%252Fconfig.g',
      '/machine/file/0:%25u002Fsys%25u002Fconfig.g',
      // .NET's `(.*)` stops at a newline: DSF reads 0:/sys/config.g, the rest is dropped.
      '/machine/file/0:/sys/config.g%0A/..%2F..%2Fgcodes%2Fa.gcode',
      // outside the drive altogether
      '/machine/file/%2F%2Fetc%2Fshadow',
      '/machine/file/0:/..%2Fdsf-config.json',
      '/machine/file/0:/macros/Park%20head.g',
      '/machine/file/0:/filaments/PLA/config.g',
      '/machine/file/0:/sys/other.csv',
      '/machine/file/0:/GCODES/a.gcode',
      '/machine/file',
      '/machine/file/',
    ];
    for (const p of spellings) {
      for (const method of ['GET', 'HEAD']) {
        const d = duetAccess(viaGateway(method, p));
        expect(d.role, `${method} ${p}`).toBe('supervisor');
      }
    }
    // file info parses a file: only job files
    expect(role('GET', '/machine/fileinfo/0%3A%2Fsys%2Fconfig.g')).toBe('supervisor');
    expect(role('GET', '/machine/fileinfo/0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g')).toBe('supervisor');
    expect(role('GET', '/Machine/FileInfo/sys/config.g')).toBe('supervisor');
    // a query cannot name another file
    expect(role('GET', '/machine/file/0%3A%2Fgcodes%2Fa.gcode?filename=0%3A%2Fsys%2Fconfig.g')).toBe(
      'supervisor',
    );
  });

  it('finding 1: other ways to the same file or to commands are supervisor (rr_ API, plugins, sockets)', () => {
    // A supervisor read (as `GET /machine/file/0:/sys/config.g`), not an audited command.
    expect(duetAccess(viaGateway('GET', '/rr_download?name=0%3A%2Fsys%2Fconfig.g'))).toMatchObject({
      role: 'supervisor',
      command: false,
    });
    for (const p of [
      '/rr_gcode?gcode=M98%20P%22evil.g%22',
      '/rr_delete?name=0%3A%2Fsys%2Fconfig.g',
      '/rr_move?old=a&new=b',
      '/rr_mkdir?dir=x',
      '/machine/MyPlugin/doSomething',
      '/machine/code',
      '/',
      '/sys/config.g',
    ]) {
      expect(duetAccess(viaGateway('GET', p)), p).toMatchObject({ role: 'supervisor', command: true });
    }
    // A WebSocket upgrade reaches DSF as a GET: only the object-model socket is a viewer read.
    for (const p of ['/machine/file/0%3A%2Fsys%2Fconfig.g', '/rr_gcode?gcode=M98', '/machine/MyPlugin/ws']) {
      expect(duetAccess(viaGateway('GET', p, { websocket: true })).role, p).toBe('supervisor');
    }
    expect(duetAccess(viaGateway('GET', '/Machine/', { websocket: true })).role).toBe('viewer');
  });

  it('finding 1: uploads are operator work only into 0:/gcodes/, however the target is spelt', () => {
    for (const p of [
      '/machine/file/0%3A%2Fgcodes%2Fa.gcode',
      '/machine/file/0%3A%2Fgcodes%2Fsub%2Fa.gcode?timeModified=2024-01-01T00%3A00%3A00Z',
      '/MACHINE/File/0%3A%2Fgcodes%2Fa.gcode',
      '/machine/file/0:/gcodes/a.gcode',
    ]) {
      expect(duetAccess(viaGateway('PUT', p)), p).toMatchObject({ role: 'operator', command: true });
    }
    for (const p of [
      '/machine/file/0%3A%2Fsys%2Fconfig.g',
      '/machine/file/0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g',
      '/machine/file/0%3A%5Cgcodes%5C..%5Csys%5Cconfig.g',
      '/machine/file/gcodes%2F..%2Fsys%2Fconfig.g',
      '/machine/file/0:/gcodes%252F..%252Fsys%252Fconfig.g',
      '/machine/file/0:/sys/config.g%0A/..%2F..%2Fgcodes%2Fa.gcode',
      '/machine/file/0%3A%2Fgcodes%2F',
      '/machine/file/0%3A%2Fgcodes',
      '/machine/file/1%3A%2Fgcodes%2Fa.gcode',
      '/machine/file/0%3A%2FGCodes%2Fa.gcode',
    ]) {
      expect(duetAccess(viaGateway('PUT', p)), p).toMatchObject({ role: 'supervisor', command: true });
    }
  });

  it('files, folders, plugins and packages changes are supervisor commands, in any case', () => {
    for (const [m, p] of [
      ['DELETE', '/machine/file/0%3A%2Fgcodes%2Fa.gcode'],
      ['POST', '/machine/file/move'],
      ['PUT', '/machine/directory/0%3A%2Fgcodes%2Fnew'],
      ['PUT', '/machine/plugin'],
      ['DELETE', '/machine/plugin'],
      ['PATCH', '/machine/plugin'],
      ['POST', '/machine/startPlugin'],
      ['POST', '/Machine/StopPlugin/'],
      ['PUT', '/machine/systemPackage'],
      ['POST', '/machine/somethingNew'],
      ['OPTIONS', '/machine/status'],
    ] as const) {
      expect(duetAccess(viaGateway(m, p)), `${m} ${p}`).toMatchObject({ role: 'supervisor', command: true });
    }
  });

  it('POST /machine/code is classified by its body in any spelling of the route', () => {
    expect(duetAccess(viaGateway('POST', '/machine/code', { body: 'M25' }))).toMatchObject({
      role: 'operator',
      command: true,
    });
    expect(duetAccess(viaGateway('POST', '/Machine/Code/?async=true', { body: 'M25' })).role).toBe(
      'operator',
    );
    expect(duetAccess(viaGateway('POST', '/Machine/Code', { body: 'M98 P"evil.g"' })).role).toBe(
      'supervisor',
    );
    expect(duetAccessNeedsBody('POST', '/machine/code')).toBe(true);
    expect(duetAccessNeedsBody('POST', '/MACHINE/code/')).toBe(true);
    expect(duetAccessNeedsBody('PUT', '/machine/file/x')).toBe(false);
    expect(duetAccessNeedsBody('GET', '/machine/code')).toBe(false);
  });
});

describe('Duet path normalisation (as DSF resolves paths)', () => {
  it('drive optional, backslashes, dot segments, .. never above the drive root', () => {
    expect(normaliseDuetPath('0:/gcodes/a.gcode')).toBe('0:/gcodes/a.gcode');
    expect(normaliseDuetPath('gcodes/a.gcode')).toBe('0:/gcodes/a.gcode');
    expect(normaliseDuetPath('/gcodes/a.gcode')).toBe('0:/gcodes/a.gcode');
    expect(normaliseDuetPath('0:gcodes\\a.gcode')).toBe('0:/gcodes/a.gcode');
    expect(normaliseDuetPath('00:///gcodes//./x/../a.gcode')).toBe('0:/gcodes/a.gcode');
    expect(normaliseDuetPath('1:/sys/config.g')).toBe('1:/sys/config.g');
    expect(normaliseDuetPath('0:/gcodes/../sys/config.g')).toBe('0:/sys/config.g');
    expect(normaliseDuetPath('0:/../sys/config.g')).toBeNull();
    expect(normaliseDuetPath('//etc/shadow')).toBeNull();
    expect(normaliseDuetPath('0:/sys/config.g\n/../../gcodes/a.gcode')).toBeNull();
    expect(normaliseDuetPath('\u0661:/sys/config.g')).toBeNull();
  });

  it('viewers read job files and the height map only', () => {
    expect(openToViewers('0:/gcodes/a.gcode')).toBe(true);
    expect(openToViewers('0:/sys/heightmap.csv')).toBe(true);
    expect(openToViewers('0:/sys/config.g')).toBe(false);
    expect(openToViewers('0:/gcodes/../sys/config.g')).toBe(false);
    expect(openToViewers('0:/macros/home.g')).toBe(false);
    expect(isJobFile('0:/gcodes/a.gcode')).toBe(true);
    expect(isJobFile('0:/gcodes/')).toBe(false);
  });
});

describe('finding 2: G-code classification', () => {
  it('the attacks forwarded for an operator need a supervisor', () => {
    for (const body of [
      'M25 (;) M98 P"evil.g"',
      'M25 (a;b) M562 P0',
      'M25M98 P"evil.g"',
      'M25:M98 P"evil.g"',
      'M112\nM25\nM999',
      'M112\nG28\nM999',
      'M112\nM999\nM999',
      'M999\nM112',
      'M999',
      // more ways RepRapFirmware and DSF can be told two different things
      'M25\rM98 P"evil.g"',
      'M25 \'M98 P"evil.g"',
      'M25\u00a0M98 P"evil.g"',
      'M25\tM98 P"evil.g"',
      '\ufeffM25\nM98 P"evil.g"',
      'M25 *12',
      'N10M98 P"evil.g"',
      'M25 "unterminated',
      'M25 {1',
      'M25 X',
      'M25.1',
      'M25 T0',
      'm25 m98 P"evil.g"',
      'echo "M25"',
      'if true\n  M25',
      'M25\u0000M98 P"evil.g"',
      // start/simulate only job files under 0:/gcodes/
      'M32 "0:/sys/config.g"',
      'M32 "0:/gcodes/../sys/config.g"',
      'M32 "0:\\gcodes\\..\\sys\\config.g"',
      'M32 "../sys/config.g"',
      'M32 "a.gcode"',
      'M32 "0:/gcodes/\'.\'./sys/config.g"',
      'M32 0:/gcodes/a.gcode',
      'M32 "0:/gcodes/a.gcode"M98 P"evil.g"',
      'M32 "0:/gcodes/a.gcode" M98 P"evil.g"',
      'M32 {"0:/gcodes/a.gcode"}',
      'M37 P"0:/sys/config.g"',
      'M37 S1',
      'M37 P"0:/gcodes/a.gcode" S1',
      // message box answers: a number or a plain string only
      'M292 P0 S1 R{move.axes[0].userPosition}',
      'M292 P0 S1 R{"} M98 P"}',
      'M292 P0 S1 R{"a(b"}',
      'M292 P0 S1 R{"a;b" ; M98}',
      'M292 P0 S1 X5',
      'M292 P0 P1',
      'M292 P{1+1} S1',
    ]) {
      expect(classifyCode(body).role, JSON.stringify(body)).toBe('supervisor');
    }
  });

  it('what the console sends stays operator; everything else is supervisor', () => {
    for (const body of [
      'M25',
      'M24\n',
      'm25',
      'M00',
      'M0 ; cancel',
      'N10 M25 ; x',
      'M112\nM999',
      'M112\r\nM999',
      'M112 M999',
      'M32 "0:/gcodes/part.gcode"',
      'M32 "0:/gcodes/a ""b"".gcode"',
      'M32 "0:/gcodes/G28 M999.gcode"',
      'M37 P"0:/gcodes/a.gcode"',
      'M292 P0 S12 R{5}',
      'M292 P0 S12 R{-2.5}',
      'M292 P0 S3 R{"it ""works"" ;ok"}',
      'M292 P1 S3',
      'M25\n; comment\n\nM24',
    ]) {
      expect(classifyCode(body).role, JSON.stringify(body)).toBe('operator');
    }
    for (const body of ['', ' \n', 'G28', 'M25\nG1 X10', 'M98 P"0:/macros/home"', 'M562 P1', 'T0']) {
      expect(classifyCode(body).role, JSON.stringify(body)).toBe('supervisor');
    }
  });

  it('tokenizes as RepRapFirmware and DSF agree, or not at all', () => {
    const t = tokenizeGcode('N3 M32 "0:/gcodes/a ""b"".gcode" ; go\nM292 P0 S7 R{"x"}');
    expect(t.ok).toBe(true);
    if (!t.ok) return;
    expect(t.commands.map((c) => c.word)).toEqual(['M32', 'M292']);
    expect(t.commands[0]?.params).toEqual([{ letter: null, kind: 'string', text: '0:/gcodes/a "b".gcode' }]);
    expect(t.commands[1]?.params.map((p) => `${p.letter}:${p.kind}:${p.text}`)).toEqual([
      'P:number:0',
      'S:number:7',
      'R:expression:{"x"}',
    ]);
    expect(tokenizeGcode('M25 (x)')).toMatchObject({ ok: false });
  });

  describe('standalone rr_* requests (issue 20)', () => {
    const decide = (method: string, raw: string) => duetAccess(viaGateway(method, raw));
    const g = (code: string) => `/rr_gcode?gcode=${encodeURIComponent(code)}`;

    it('reads are viewer reads: model, reply, listings, job files, the height map', () => {
      for (const p of [
        '/rr_model?key=&flags=d99fn',
        '/rr_model?key=seqs&flags=d99vno',
        '/rr_reply',
        '/rr_filelist?dir=0%3A%2Fgcodes&first=0',
        '/rr_download?name=0%3A%2Fgcodes%2Fa.gcode',
        '/rr_download?name=0%3A%2Fsys%2Fheightmap.csv',
        '/rr_fileinfo?name=0%3A%2Fgcodes%2Fa.gcode',
        '/rr_fileinfo',
        '/rr_thumbnail?name=0%3A%2Fgcodes%2Fa.gcode&offset=100',
        '/RR_MODEL?key=state',
      ])
        expect(decide('GET', p), p).toMatchObject({ role: 'viewer', command: false });
    });

    it('classifies rr_gcode by the G-code in its query, exactly as POST /machine/code', () => {
      for (const code of ['M25', 'M24', 'M0', 'M112\nM999', 'M292 P0 S3', 'M32 "0:/gcodes/a.gcode"']) {
        expect(decide('GET', g(code)), code).toMatchObject({ role: 'operator', command: true });
        expect(decide('GET', g(code)).role).toBe(classifyCode(code).role);
      }
      for (const code of [
        'M999',
        'M112 M999 G1 X10',
        'G1 X10',
        'M104 S250',
        'M562 P1',
        'M98 P"evil.g"',
        'M32 "0:/sys/config.g"',
        'M25\nG28',
        '',
      ])
        expect(decide('GET', g(code)), code).toMatchObject({ role: 'supervisor', command: true });
      // Given twice, RRF and the gateway could read different ones: not classified.
      // (The gateway refuses a repeated name outright; the policy refuses it too.)
      expect(splitTarget('/rr_gcode?gcode=M25&gcode=G28')).toHaveProperty('error');
      const twice = new URLSearchParams([
        ['gcode', 'M25'],
        ['gcode', 'G28'],
      ]);
      expect(duetAccess({ method: 'GET', path: '/rr_gcode', query: twice }).role).toBe('supervisor');
      expect(decide('GET', '/rr_gcode?gcode=M25&GCODE=G28').role).toBe('supervisor');
      // Without the query the G-code is missing: no operator work.
      expect(decide('GET', '/rr_gcode').role).toBe('supervisor');
    });

    it('uploads are operator work only into 0:/gcodes/; file changes are supervisor commands', () => {
      expect(decide('POST', '/rr_upload?name=0%3A%2Fgcodes%2Fa.gcode&crc32=01020304')).toMatchObject({
        role: 'operator',
        command: true,
      });
      for (const p of [
        '/rr_upload?name=0%3A%2Fsys%2Fconfig.g',
        '/rr_upload?name=0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g',
        '/rr_upload?name=0%3A%2Fgcodes%2Fa.g&NAME=0%3A%2Fsys%2Fconfig.g',
        '/rr_upload',
      ])
        expect(decide('POST', p), p).toMatchObject({ role: 'supervisor', command: true });
      for (const p of [
        '/rr_delete?name=0%3A%2Fgcodes%2Fa.g',
        '/rr_move?old=a&new=b',
        '/rr_mkdir?dir=0%3A%2Fgcodes%2Fx',
      ])
        expect(decide('GET', p), p).toMatchObject({ role: 'supervisor', command: true });
      for (const p of [
        '/rr_download?name=0%3A%2Fsys%2Fconfig.g',
        '/rr_download?name=0%3A%2Fgcodes%2F..%2Fsys%2Fconfig.g',
        '/rr_download?name=0%3A%2Fgcodes%2Fa.g&Name=0%3A%2Fsys%2Fconfig.g',
        '/rr_fileinfo?name=0%3A%2Fmacros%2Fx.g',
      ])
        expect(decide('GET', p).role, p).toBe('supervisor');
      // Unknown rr_ requests, and other methods, are supervisor.
      expect(decide('GET', '/rr_status?type=3').role).toBe('supervisor');
      expect(decide('PUT', '/rr_gcode?gcode=M25').role).toBe('supervisor');
    });
  });
});
