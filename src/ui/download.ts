import { CSV_MIME } from './csv';

/**
 * The one way the console offers a file it made or fetched: a Blob behind an object URL, a
 * temporary `<a download>` clicked, the URL revoked afterwards (later, not at once: some browsers
 * read it after the click returns).
 */
export function downloadFile(
  filename: string,
  content: Blob | string,
  type = 'application/octet-stream',
  revokeAfterMs = 10_000,
): void {
  const blob = typeof content === 'string' ? new Blob([content], { type }) : content;
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  a.href = url;
  a.download = filename;
  a.rel = 'noopener';
  a.style.display = 'none';
  document.body.appendChild(a);
  try {
    a.click();
  } finally {
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), revokeAfterMs);
  }
}

/** Text as a file (a log, a report). */
export function downloadText(filename: string, text: string, type = 'text/plain;charset=utf-8'): void {
  downloadFile(filename, text, type);
}

/** CSV text (from `toCsv` / `csvFromColumns`) as a `.csv` file. */
export function downloadCsv(filename: string, csv: string): void {
  downloadFile(filename, csv, CSV_MIME);
}
