import { afterEach, describe, expect, it } from 'vitest';
import type { AuditEntry } from './audit';
import { CSV_COLUMNS, toCsv } from './audit-csv';
import { consoleFetch, gatewayFor, type Cleanups } from './test-util';

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

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

  it('is streamed from the table, page by page, newest first, with the filters of the API', async () => {
    const gw = await gatewayFor(cleanups, []);
    const base = Date.UTC(2026, 2, 18);
    for (let n = 0; n < 1100; n++)
      gw.gw.audit.append(
        entry({ time: new Date(base + n * 1000).toISOString(), machine: n % 2 ? 'a' : 'b', detail: `#${n}` }),
      );
    const r = await consoleFetch(`${gw.url}/api/audit.csv?machine=a`);
    expect(r.status).toBe(200);
    expect(r.headers.get('content-type')).toBe('text/csv; charset=utf-8');
    const body = Buffer.from(await r.arrayBuffer()).toString('utf8');
    const want = await gw.gw.audit.filtered({ machine: 'a' });
    expect(want).toHaveLength(550);
    expect(want[0]?.detail).toBe('#1099');
    expect(body).toBe(toCsv(want));
  });
});
