import { describe, expect, it } from 'vitest';
import { CSV_COLUMNS, toCsv, type AuditEntry } from './audit';

const entry = (e: Partial<AuditEntry>): AuditEntry => ({
  time: '2026-03-18T12:00:00.000Z',
  type: 'command',
  result: 'ok',
  user: 'vera',
  source: 'gateway',
  ...e,
});

/** Splits our own output (no quoted line breaks in these cases) into rows of raw fields. */
function rows(csv: string): string[][] {
  return csv
    .replace(/^\uFEFF/, '')
    .trimEnd()
    .split('\r\n')
    .map((l) => l.split(/,(?=(?:[^"]*"[^"]*")*[^"]*$)/));
}

describe('audit CSV (GET /api/audit.csv)', () => {
  it('defuses formulas in what users and controllers wrote', () => {
    const csv = toCsv([
      entry({
        user: '=HYPERLINK("http://evil.example","x")',
        path: '+1',
        label: '-2+3',
        detail: '@SUM(A1)',
        error: '\t=1',
        status: -1,
      }),
    ]);
    const [header, row] = rows(csv);
    expect(header).toEqual(CSV_COLUMNS);
    const cell = (c: keyof AuditEntry) => row![CSV_COLUMNS.indexOf(c)];
    expect(cell('user')).toBe(`"'=HYPERLINK(""http://evil.example"",""x"")"`);
    expect(cell('path')).toBe(`"'+1"`);
    expect(cell('label')).toBe(`"'-2+3"`);
    expect(cell('detail')).toBe(`"'@SUM(A1)"`);
    expect(cell('error')).toBe(`"'\t=1"`);
    // A number is a number.
    expect(cell('status')).toBe('-1');
    expect(cell('time')).toBe('2026-03-18T12:00:00.000Z');
  });

  it('is RFC 4180 with a UTF-8 byte order mark for spreadsheets', () => {
    const csv = toCsv([entry({ user: 'Jürgen, "J"', detail: 'two\nlines' })]);
    expect(csv.startsWith('\uFEFFtime,type,result,user,')).toBe(true);
    expect(csv.endsWith('\r\n')).toBe(true);
    expect(csv).toContain(`,"Jürgen, ""J""",`);
    expect(csv).toContain(`,"two\nlines",`);
    // Missing fields are empty.
    expect(csv.split('\r\n')[1]).toMatch(/^2026-03-18T12:00:00.000Z,command,ok,"Jürgen, ""J""",,/);
  });
});
