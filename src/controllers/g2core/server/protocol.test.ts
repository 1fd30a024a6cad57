import { readdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import { BoardSim, parseRelaxed } from './board-sim';
import { lineProblem, parseBoardLine, sendableLine, wireBytes, type BoardMessage } from './protocol';
import { pickBoardPort, classifyOpenError } from './link';

/** The wire protocol against the captures in ../shared/fixtures/g2core (SOURCES.md). */

const FIX = path.resolve(__dirname, '../../../../../shared/fixtures/g2core');

function session(name: string): Array<{ dir: 'tx' | 'rx'; raw: string }> {
  return readFileSync(path.join(FIX, 'sessions', name), 'utf8')
    .split('\n')
    .filter((l) => l.trim() !== '')
    .map((l) => JSON.parse(l) as { dir: 'tx' | 'rx'; raw: string });
}

describe('g2core serial protocol', () => {
  it('classifies every received line of every captured session, none as noise', () => {
    const files = readdirSync(path.join(FIX, 'sessions')).filter((f) => f.endsWith('.jsonl'));
    expect(files.length).toBeGreaterThan(5);
    const seen = new Set<BoardMessage['type']>();
    for (const f of files) {
      for (const e of session(f).filter((x) => x.dir === 'rx')) {
        const m = parseBoardLine(e.raw);
        expect(m.type, `${f}: ${e.raw}`).not.toBe('noise');
        seen.add(m.type);
      }
    }
    expect([...seen].sort()).toEqual(['banner', 'err', 'er', 'qr', 'response', 'sr'].sort());
  });

  it('reads the status from f[1] only, in the g2core, wiki and TinyG footer forms and inside r', () => {
    expect(parseBoardLine('{"r":{"spe":null},"f":[1,100,9]}')).toEqual({
      type: 'response',
      r: { spe: null },
      status: 100,
    });
    expect(parseBoardLine('{"r":{"jv":4},"f":[1,0,7,7333]}')).toMatchObject({ status: 0 });
    expect(parseBoardLine('{"r":{"xvm":1,"f":[3,108,4]}}')).toEqual({
      type: 'response',
      r: { xvm: 1 },
      status: 108,
    });
    const banner = JSON.parse(
      readFileSync(path.join(FIX, 'responses/startup-system-ready-101.03.json'), 'utf8'),
    ) as unknown;
    expect(parseBoardLine(JSON.stringify(banner))).toMatchObject({
      type: 'banner',
      info: { hp: 'ArduinoDue', fb: 101.03 },
    });
    const er = JSON.parse(
      readFileSync(path.join(FIX, 'responses/exception-report-kill-job-101.03.json'), 'utf8'),
    ) as unknown;
    expect(parseBoardLine(JSON.stringify(er))).toEqual({
      type: 'er',
      status: 207,
      msg: 'Kill job - Job killed by ^d',
    });
    expect(parseBoardLine(readFileSync(path.join(FIX, 'responses/enq-ack.json'), 'utf8'))).toEqual({
      type: 'ack',
    });
    // Hostile or broken lines are noise, never a throw.
    for (const bad of ['', '\u0000\u00ff', '[1,2]', '{"r":[]}', '{"f":[1,"x"]}', '{'.repeat(5000)])
      expect(parseBoardLine(bad).type).toBe('noise');
    expect(parseBoardLine('{"r":{},"f":[1,"7",3]}')).toMatchObject({ status: 0 });
  });

  it('refuses lines the board would act on at once or could not hold', () => {
    expect(lineProblem('G1 X1')).toBeNull();
    expect(lineProblem('G1 X' + '1'.repeat(248))).toBeNull(); // 253 bytes with "\n"
    expect(lineProblem('G1 X' + '1'.repeat(249))).toMatch(/254 bytes/);
    expect(lineProblem('G1 X1 !')).toMatch(/at once/);
    expect(lineProblem('G1\u0018X1')).toMatch(/control/);
    // Checked as the bytes written (one per character): U+0118 would be ^X, U+0121 "!", U+010A "\n".
    expect(lineProblem('G1 X1 \u0118')).toMatch(/U\+0118 \(the board would read \^X, a board reset\)/);
    expect(lineProblem('G1 X1 \u0104')).toMatch(/\^D, a job kill/);
    expect(lineProblem('G1 X1 \u0121')).toMatch(/"!"/);
    expect(lineProblem('G1 X1 \u010a')).toMatch(/a line break/);
    expect(lineProblem('G1 X1 \u00e9')).toMatch(/outside printable ASCII/);
    expect(lineProblem('G1 X1 \u{1f600}')).toMatch(/outside printable ASCII/);
    expect(lineProblem('G1\tX1')).toBeNull();
    expect(wireBytes('G1\tX1\n')).toEqual(Buffer.from('G1\tX1\n'));
    expect(wireBytes('!')).toEqual(Buffer.from([0x21]));
    expect(wireBytes('\x18')).toEqual(Buffer.from([0x18]));
    expect(wireBytes('G1 \u0118\n')).toMatch(/\^X/);
    expect(wireBytes('G1 X1')).toBe('not a whole line');
    expect(wireBytes('G1 \x18 X1\n')).toMatch(/control byte|\^X/);
    expect(sendableLine('G1 X1 (fast!) ; note %')).toBe('G1 X1');
    expect(sendableLine('%')).toBeNull();
    expect(sendableLine('(only a comment)')).toBeNull();
    expect(sendableLine('{"xvm":null}')).toBe('{"xvm":null}');
  });

  it('the host relaxed JSON of the captures parses as the board reads it', () => {
    const tx = session('cncjs-connect-g2core-101.03.jsonl').filter((e) => e.dir === 'tx');
    expect(tx.map((e) => parseRelaxed(e.raw))).toEqual([
      { ej: 1 },
      { jv: 4 },
      { qv: 1 },
      { sv: 1 },
      { si: 100 },
      { spe: null },
    ]);
  });

  it('picks a board by its USB ids and words open errors for the machine page', () => {
    expect(
      pickBoardPort([{ path: '/dev/ttyS0' }, { path: '/dev/ttyUSB0', vendorId: '0403', productId: '6015' }])
        ?.path,
    ).toBe('/dev/ttyUSB0');
    expect(pickBoardPort([{ path: '/dev/ttyACM0', vendorId: '2341', productId: '0043' }])).toBeNull();
    expect(
      classifyOpenError(new Error('Error: Resource temporarily unavailable Cannot lock port'), '/dev/x'),
    ).toMatchObject({ state: 'busy' });
    expect(
      classifyOpenError(
        Object.assign(new Error('Error: No such file or directory, cannot open /dev/x'), { code: 'ENOENT' }),
        '/dev/x',
      ),
    ).toMatchObject({ state: 'unplugged' });
    expect(
      classifyOpenError(new Error('Error: Permission denied, cannot open /dev/x'), '/dev/x'),
    ).toMatchObject({
      state: 'error',
      detail: expect.stringMatching(/dialout/),
    });
    // Windows says "Access denied" for a port another program has open.
    expect(classifyOpenError(new Error('Opening COM3: Access denied'), 'COM3')).toMatchObject({
      state: 'busy',
    });
  });
});

describe('simulated board (quirks from the research notes)', () => {
  function board(opts: ConstructorParameters<typeof BoardSim>[0] = {}): { b: BoardSim; out: string[] } {
    const out: string[] = [];
    const b = new BoardSim({ ...opts, setTimeout: () => null, clearTimeout: () => undefined });
    b.connect((l) => out.push(l));
    return { b, out };
  }

  it('"%" flushes only in feedhold or right after "!"; elsewhere it is part of the line', () => {
    const { b } = board();
    b.receive('G1 X1\n');
    expect(b.stat).toBe(5);
    b.receive('%\n');
    // Not in hold: "%" is read as a line (a program delimiter), not acted on.
    expect(b.controls).toEqual([]);
    expect(b.received.at(-1)).toBe('%');
    b.receive('!%');
    expect(b.controls).toEqual(['!', '%']);
    expect(b.stat).toBe(6);
  });

  it('answers ENQ with {"ack":true}, ^D with the 207 exception report and stat 4, an unknown key with 100 and the err line', () => {
    const { b, out } = board();
    b.receive('\x05');
    expect(out.at(-1)).toBe('{"ack":true}');
    b.receive('{spe:n}\n');
    expect(out.slice(-2)).toEqual([
      '{"r":{"spe":null},"f":[1,100,9]}', // 101.03: the line's length + 2, as the recorded sessions
      '{"err":{"code":100,"msg":"Unrecognized command or config name"}}',
    ]);
    b.receive('{sv:1}\nG1 X1\n\x04');
    expect(out).toContain('{"er":{"fb":101.03,"st":207,"msg":"Kill job - Job killed by ^d"}}');
    expect(b.stat).toBe(4);
  });

  it('TinyG footers have 4 elements; a line of 254 bytes answers 107', () => {
    const { b, out } = board({ firmware: 'tinyg' });
    b.receive('{xvm:n}\n');
    expect((JSON.parse(out.at(-1)!) as { f: number[] }).f).toHaveLength(4);
    b.receive('G1 X' + '1'.repeat(249) + '\n');
    expect(parseBoardLine(out.at(-1)!)).toMatchObject({ status: 107 });
  });
});
