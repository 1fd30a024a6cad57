import type { ServerResponse } from 'node:http';
// The pure writer (no DOM); src/ui is the bottom layer, so the gateway and the browser share it.
import { csvRow, toCsv as writeCsv, UTF8_BOM } from '../src/ui/csv';
import type { AuditEntry, AuditLog, AuditQuery } from './audit';

/** The audit log over HTTP: `GET /api/audit`'s query parameters and `GET /api/audit.csv`. */

function parseTime(v: string | null): number | undefined {
  if (!v) return undefined;
  if (/^\d+$/.test(v)) return Number(v);
  const t = Date.parse(v);
  return Number.isNaN(t) ? undefined : t;
}

export function auditQueryFrom(params: URLSearchParams): AuditQuery {
  const num = (k: string): number | undefined => {
    const v = params.get(k);
    if (v === null || v === '' || !/^\d+$/.test(v)) return undefined;
    return Number(v);
  };
  return {
    offset: num('offset'),
    limit: num('limit'),
    machine: params.get('machine') || undefined,
    user: params.get('user') || undefined,
    result: params.get('result') || undefined,
    from: parseTime(params.get('from')),
    to: parseTime(params.get('to')),
  };
}

export const CSV_COLUMNS: Array<keyof AuditEntry> = [
  'time',
  'type',
  'result',
  'user',
  'onBehalfOf',
  'machine',
  'method',
  'path',
  'commandId',
  'clientCommand',
  'label',
  'status',
  'detail',
  'error',
  'role',
  'address',
  'source',
];

/**
 * The audit log as CSV, through the console's one writer (src/ui/csv.ts: RFC 4180, formula
 * defusing). User names, paths, labels and controller messages are not ours: a cell such as
 * `=HYPERLINK(…)` is written as text, never as a formula a spreadsheet would run. With a UTF-8
 * byte order mark: the export is opened in spreadsheets, and user names are not ASCII-only.
 */
export function toCsv(entries: readonly AuditEntry[]): string {
  return writeCsv(
    CSV_COLUMNS,
    entries.map((e) => CSV_COLUMNS.map((c) => e[c])),
    { bom: true },
  );
}

/**
 * `GET /api/audit.csv`: the same CSV, streamed a page of rows at a time, waiting while the
 * browser is slow (never the whole log in memory); a browser that leaves stops it.
 */
export async function streamCsv(audit: AuditLog, q: AuditQuery, res: ServerResponse): Promise<void> {
  const pages = audit.pages(q);
  // The first page is read before the answer starts: a database that cannot be read is an error
  // status (503), not a cut file.
  let page = pages.next();
  res.writeHead(200, {
    'Content-Type': 'text/csv; charset=utf-8',
    'Content-Disposition': 'attachment; filename="shopdeck-audit.csv"',
    'Cache-Control': 'no-store',
  });
  let ok = res.write(`${UTF8_BOM}${csvRow(CSV_COLUMNS)}\r\n`);
  while (!page.done) {
    if (!ok)
      await new Promise<void>((resolve) => {
        const go = (): void => {
          res.off('drain', go);
          res.off('close', go);
          resolve();
        };
        res.on('drain', go);
        res.on('close', go);
      });
    if (res.destroyed) return;
    ok = res.write(page.value.map((e) => `${csvRow(CSV_COLUMNS.map((c) => e[c]))}\r\n`).join(''));
    page = pages.next();
  }
  res.end();
}
