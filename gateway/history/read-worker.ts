import { parentPort, workerData } from 'node:worker_threads';
import Database from 'better-sqlite3';
import { csvRow, UTF8_BOM } from '../../src/ui/csv';
import type { StatsExport } from '../../src/fleet/server-part';
import { answerHistory } from './answers';
import { CHUNK_CHARS, CREDIT_WINDOW, type FromWorker, type ReadJob, type ToWorker } from './read-protocol';
import { HistoryReader } from './reader';

/**
 * A read worker (started by reads.ts through read-worker.mjs): answers history questions off the
 * gateway's thread, each on a read-only connection of its own (WAL: readers never block the
 * recorder, which keeps the gateway's connection). An export is sent in chunks, at most
 * `CREDIT_WINDOW` ahead of what the gateway wrote out to its client; between chunks the worker
 * serves its other jobs and hears a cancel (the client went away).
 */

const port = parentPort;
if (!port) throw new Error('read-worker.ts runs as a worker thread');

/** The families' exports of their stored days (reads.ts passes their modules), loaded before any question. */
const statsExports = new Map<string, StatsExport>();
for (const e of (workerData as { statsExports?: Array<{ route: string; module: string }> } | null)
  ?.statsExports ?? []) {
  const m = (await import(e.module)) as { statsExport: StatsExport };
  statsExports.set(e.route, m.statsExport);
}

interface Running {
  cancelled: boolean;
  credit: number;
  wake: (() => void) | null;
}

const running = new Map<number, Running>();

function post(m: FromWorker): void {
  port?.postMessage(m);
}

/** Lets the worker's other messages in (credits, cancels, other jobs' questions). */
const breathe = (): Promise<void> => new Promise((r) => setImmediate(r));

async function run(id: number, file: string, job: ReadJob): Promise<void> {
  const self: Running = { cancelled: false, credit: CREDIT_WINDOW, wake: null };
  running.set(id, self);
  let db: Database.Database | null = null;
  try {
    db = new Database(file, { readonly: true, fileMustExist: true });
    db.pragma('busy_timeout = 2000');
    const reader = new HistoryReader({
      db,
      file,
      now: () => job.env.now,
      retention: () => job.env.settings.retention,
      live: (m) => job.live[m],
    });
    const a = answerHistory(
      job.route,
      job.csv,
      new URLSearchParams(job.params),
      job.env,
      reader,
      statsExports,
    );
    if (a.type === 'json') {
      post({ type: 'json', id, status: a.status, text: JSON.stringify(a.body) });
      return;
    }
    post({ type: 'csv-head', id, name: a.name, truncated: a.truncated === true });
    const send = async (text: string): Promise<void> => {
      post({ type: 'chunk', id, text });
      self.credit--;
      await breathe();
      while (self.credit <= 0 && !self.cancelled) await new Promise<void>((r) => (self.wake = r));
    };
    let buf = UTF8_BOM + csvRow(a.header) + '\r\n';
    // for…of: leaving the loop (a cancel) returns the iterator, which ends its statement.
    for (const row of a.rows) {
      if (self.cancelled) break;
      buf += csvRow(row) + '\r\n';
      if (buf.length >= CHUNK_CHARS) {
        await send(buf);
        buf = '';
      }
    }
    if (self.cancelled) return;
    if (buf) post({ type: 'chunk', id, text: buf });
    post({ type: 'end', id });
  } catch (e) {
    post({ type: 'error', id, message: e instanceof Error ? e.message : String(e) });
  } finally {
    running.delete(id);
    try {
      db?.close();
    } catch {
      /* closing a read-only connection cannot lose anything */
    }
    post({ type: 'done', id });
  }
}

port.on('message', (m: ToWorker) => {
  if (m.type === 'run') {
    void run(m.id, m.file, m.job);
    return;
  }
  const r = running.get(m.id);
  if (!r) return;
  if (m.type === 'credit') r.credit++;
  else r.cancelled = true;
  const wake = r.wake;
  r.wake = null;
  wake?.();
});
