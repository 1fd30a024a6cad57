/**
 * The one CSV writer (RFC 4180: fields with `"`, `,`, CR or LF quoted, `"` doubled, CRLF line
 * ends). Every CSV the console writes goes through it: the TouchCut statistics tables in the
 * browser and the audit export (`GET /api/audit.csv`) in the gateway. It is pure (no DOM), so the
 * gateway imports it from Node; offering a file for download is `downloadFile` in ./download.ts.
 *
 * Cells come from users and controllers (user names, paths, labels, vendor messages), and a
 * spreadsheet runs a cell that starts with `=`, `+`, `-`, `@`, tab or carriage return as a formula
 * (OWASP "CSV Injection"). Such a text cell gets a leading `'` and is quoted. Numbers stay
 * numbers (`-3` is written as it is); text is defused whatever it looks like, `"-3"` included.
 */

export type CsvValue = string | number | boolean | null | undefined;

export interface CsvColumn<T> {
  label: string;
  value: (row: T) => CsvValue;
}

export interface CsvOptions {
  /**
   * Start with a UTF-8 byte order mark, so a spreadsheet opening the file reads it as UTF-8 (Excel
   * otherwise guesses a legacy code page and garbles "Jürgen"). For files people open in one.
   */
  bom?: boolean;
}

export const CSV_MIME = 'text/csv;charset=utf-8';
export const UTF8_BOM = '\uFEFF';

/** Characters that make a spreadsheet read a cell as a formula when they come first. */
const FORMULA_START = /^[=+\-@\t\r]/;
const NEEDS_QUOTES = /[",\r\n]/;

/** Text a spreadsheet would run as a formula gets a leading apostrophe; anything else is returned as is. */
export function defuseFormula(text: string): string {
  return FORMULA_START.test(text) ? `'${text}` : text;
}

/** One field, quoted and defused. */
export function csvCell(value: CsvValue): string {
  if (value === null || value === undefined) return '';
  if (typeof value === 'number') return Number.isFinite(value) ? String(value) : '';
  if (typeof value === 'boolean') return String(value);
  const text = defuseFormula(value);
  // A defused cell is quoted too (OWASP): the apostrophe then stays inside the field.
  return NEEDS_QUOTES.test(text) || text !== value ? `"${text.replace(/"/g, '""')}"` : text;
}

/** One record, without the line end. */
export function csvRow(values: readonly CsvValue[]): string {
  return values.map(csvCell).join(',');
}

/** A header and rows of values; every record (the last too) ends in CRLF. */
export function toCsv(
  header: readonly CsvValue[],
  rows: Iterable<readonly CsvValue[]>,
  opts: CsvOptions = {},
): string {
  const lines = [csvRow(header)];
  for (const r of rows) lines.push(csvRow(r));
  return (opts.bom ? UTF8_BOM : '') + lines.join('\r\n') + '\r\n';
}

/** Rows of objects through column declarations (label and how to read the value). */
export function csvFromColumns<T>(
  columns: readonly CsvColumn<T>[],
  rows: readonly T[],
  opts: CsvOptions = {},
): string {
  return toCsv(
    columns.map((c) => c.label),
    rows.map((r) => columns.map((c) => c.value(r))),
    opts,
  );
}
