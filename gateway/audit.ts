import {
  closeSync,
  existsSync,
  fstatSync,
  fsyncSync,
  mkdirSync,
  openSync,
  readSync,
  statSync,
  writeSync,
} from 'node:fs';
import * as fsp from 'node:fs/promises';
import type { FileHandle } from 'node:fs/promises';
import path from 'node:path';
// The pure writer (no DOM); src/ui is the bottom layer, so the gateway and the browser share it.
import { toCsv as writeCsv } from '../src/ui/csv';
import { loggerFromEnv, type Logger } from './log';

/**
 * The audit log: one JSON object per line in `<data folder>/audit.jsonl`. Appended by the
 * gateway (commands it forwarded to hardware or to its own simulators, logins, refusals) and by
 * `npm run user` (role changes). `source: "client"` only appears in logs written before the
 * demo fleet moved into the server, when the page audited its own simulators.
 */

export type AuditType =
  | 'command'
  | 'refused'
  | 'login'
  | 'login-failed'
  | 'logout'
  | 'session-expired'
  | 'elevate'
  | 'elevate-failed'
  | 'elevate-end'
  | 'user-added'
  | 'user-removed'
  | 'role-change'
  | 'password-change'
  /** A controller's TLS certificate trusted on first use, or forgotten by a supervisor. */
  | 'tls-trust'
  | 'tls-forget'
  /** What the gateway's watch saw a machine do (watch.ts): job started/paused/ended, alarms. */
  | 'machine'
  /** A person acknowledged an alarm (the alarm centre, alarms.ts). */
  | 'alarm-ack'
  /** A supervisor changed the server settings (the alarm webhook). */
  | 'settings';

export type AuditResult = 'ok' | 'error' | 'refused' | 'failed';

export interface AuditEntry {
  /** ISO time */
  time: string;
  type: AuditType;
  result: AuditResult;
  /** Who: a user name, "anonymous" in open mode, the OS user for the command line. */
  user: string;
  source: 'gateway' | 'client' | 'cli';
  machine?: string;
  method?: string;
  /** Controller path with query, secrets redacted. */
  path?: string;
  /** The `X-Shopdeck-Command` id the client sent ("xtool.pause"). */
  commandId?: string;
  /** What the request does, from the family's access declaration. */
  label?: string;
  /** Controller's HTTP status. */
  status?: number;
  /** The outcome in words, as the client saw it ("job paused"). */
  detail?: string;
  /** Error text when there was no answer, or the reason for a refusal. */
  error?: string;
  /** Role that was needed (refusals) or granted (role changes, elevation). */
  role?: string;
  address?: string;
  /** A supervisor acting on an operator's session through PIN elevation. */
  onBehalfOf?: string;
}

export interface AuditQuery {
  offset?: number;
  limit?: number;
  machine?: string;
  user?: string;
  result?: string;
  /** ms since epoch or ISO, inclusive */
  from?: number;
  to?: number;
  /** Only these machines (a user limited to some machines); entries without a machine stay. */
  machines?: readonly string[] | null;
}

export const AUDIT_FILE = 'audit.jsonl';
/** Rotation: the current file is renamed `audit.1.jsonl` when the next write would pass this size. */
export const DEFAULT_AUDIT_MAX_BYTES = 10 * 1024 * 1024;
/** Files kept, the current one included: `audit.jsonl`, `audit.1.jsonl` … `audit.4.jsonl`. */
export const DEFAULT_AUDIT_KEEP = 5;
/** Newest entries held in memory: the first pages of `GET /api/audit` never touch the disk. */
export const DEFAULT_AUDIT_INDEX = 5000;

/** `audit.jsonl` (n = 0), then the rotated files `audit.1.jsonl`, `audit.2.jsonl` …, older as n grows. */
export function auditFileName(n: number): string {
  return n === 0 ? AUDIT_FILE : `audit.${n}.jsonl`;
}

/** The file system calls of the queued writer and of the reader of older pages (tests wrap them). */
export type AuditFs = Pick<typeof fsp, 'open' | 'rename' | 'unlink' | 'stat' | 'mkdir' | 'readdir'>;

export interface AuditLogOptions {
  /**
   * `queue` (the gateway): appends return at once and are written in order, by one file handle,
   * in the background; batches holding a command (or another entry in `DURABLE_TYPES`) are fsynced
   * as soon as they are written; rotation by size. `direct` (default; `npm run user`, a process
   * that exits right after): each append is written and fsynced before it returns; never rotates.
   */
  writer?: 'queue' | 'direct';
  maxBytes?: number;
  keep?: number;
  indexSize?: number;
  fs?: AuditFs;
  log?: Logger;
}

/**
 * Entries whose batch is fsynced as soon as it is written: commands, refusals, logins and every
 * change of who may do what. Ends of sessions (logout, expiry, end of a PIN unlock) are written
 * in order with the rest and reach the disk with the next fsync, `flush()` or the system's own.
 */
export const DURABLE_TYPES: ReadonlySet<AuditType> = new Set<AuditType>([
  'command',
  'refused',
  'login',
  'login-failed',
  'elevate',
  'elevate-failed',
  'user-added',
  'user-removed',
  'role-change',
  'password-change',
  'tls-trust',
  'tls-forget',
  'machine',
  'alarm-ack',
  'settings',
]);

/** An entry in memory: where it is on disk once written (`seg` null: still queued). */
interface Slot {
  e: AuditEntry;
  /** The line to write (with its newline); dropped once written. */
  line: Buffer | null;
  /** The file it is in, as a number that does not change when files are renamed (see `seg`). */
  seg: number | null;
  offset: number;
  durable: boolean;
}

/** A count of the entries older than the in-memory index that match a filter. */
interface Counter {
  match: (e: AuditEntry) => boolean;
  n: number;
  ready: boolean;
}

type LineFn = (line: Buffer, start: number, end: number) => boolean;

const NEWLINE = Buffer.from('\n');
const CHUNK = 64 * 1024;
/** At most this much is written by one call (a burst is written in several). */
const MAX_BATCH_BYTES = 1024 * 1024;
/** Entries waiting while the disk refuses them (full, read-only): beyond this the oldest go. */
const MAX_QUEUED = 100_000;
const MAX_COUNTERS = 32;
const RETRY_MS = 1000;

const noop = (): void => undefined;

function isNotFound(e: unknown): boolean {
  return (e as NodeJS.ErrnoException | null)?.code === 'ENOENT';
}

/**
 * Splits a region of a file read from its end backwards, chunk by chunk, into lines, newest
 * first. Lines are split on the newline byte (never part of a multi-byte UTF-8 character), so a
 * chunk boundary inside a character does no harm. `end` of a line excludes its newline.
 */
class BackwardLines {
  private parts: Buffer[] = [];
  private lineEnd: number;

  constructor(end: number) {
    this.lineEnd = end;
  }

  /** The chunk found at `pos`; chunks come from the end of the region towards its start. */
  feed(chunk: Buffer, pos: number, onLine: LineFn): boolean {
    let hi = chunk.length;
    while (hi > 0) {
      const nl = chunk.lastIndexOf(0x0a, hi - 1);
      if (nl === -1) break;
      const piece = chunk.subarray(nl + 1, hi);
      const text = this.parts.length ? Buffer.concat([piece, ...this.parts]) : piece;
      this.parts = [];
      const end = this.lineEnd;
      this.lineEnd = pos + nl;
      hi = nl;
      if (text.length > 0 && !onLine(text, pos + nl + 1, end)) return false;
    }
    if (hi > 0) this.parts.unshift(chunk.subarray(0, hi));
    return true;
  }

  /** The region's first line (it has no newline before it). */
  finish(start: number, onLine: LineFn): boolean {
    if (!this.parts.length) return true;
    const text = Buffer.concat(this.parts);
    this.parts = [];
    return onLine(text, start, this.lineEnd);
  }
}

/** Lines of `[0, end)` of a file, newest first; false when `onLine` stopped the reading. */
function readLinesBackSync(fd: number, end: number, onLine: LineFn): boolean {
  const lines = new BackwardLines(end);
  let pos = end;
  while (pos > 0) {
    const len = Math.min(CHUNK, pos);
    pos -= len;
    const buf = Buffer.allocUnsafe(len);
    let got = 0;
    while (got < len) {
      const n = readSync(fd, buf, got, len - got, pos + got);
      if (n === 0) throw new Error('the audit file became shorter while it was read');
      got += n;
    }
    if (!lines.feed(buf, pos, onLine)) return false;
  }
  return lines.finish(0, onLine);
}

/** The same, streamed without blocking (older pages, CSV export). */
async function readLinesBack(fh: FileHandle, end: number, onLine: LineFn): Promise<boolean> {
  const lines = new BackwardLines(end);
  let pos = end;
  while (pos > 0) {
    const len = Math.min(CHUNK, pos);
    pos -= len;
    const buf = Buffer.allocUnsafe(len);
    let got = 0;
    while (got < len) {
      const { bytesRead } = await fh.read(buf, got, len - got, pos + got);
      if (bytesRead === 0) throw new Error('the audit file became shorter while it was read');
      got += bytesRead;
    }
    if (!lines.feed(buf, pos, onLine)) return false;
  }
  return lines.finish(0, onLine);
}

/** An entry, `'blank'` for an empty line, null for anything else (a torn or foreign line). */
function parseLine(buf: Buffer): AuditEntry | 'blank' | null {
  const text = buf.toString('utf8');
  if (!text.trim()) return 'blank';
  try {
    const e = JSON.parse(text) as unknown;
    if (e && typeof e === 'object' && typeof (e as AuditEntry).time === 'string') return e as AuditEntry;
  } catch {
    // a torn line (crash while writing) or not ours
  }
  return null;
}

async function writeAll(fh: FileHandle, buf: Buffer): Promise<void> {
  let done = 0;
  while (done < buf.length) {
    const { bytesWritten } = await fh.write(buf, done, buf.length - done);
    done += bytesWritten;
  }
}

function writeAllSync(fd: number, buf: Buffer): void {
  let done = 0;
  while (done < buf.length) done += writeSync(fd, buf, done, buf.length - done);
}

/** Whether an entry passes a query's filters. */
export function auditMatcher(q: AuditQuery): (e: AuditEntry) => boolean {
  return (e) => {
    if (q.machine && e.machine !== q.machine) return false;
    if (q.machines && e.machine !== undefined && !q.machines.includes(e.machine)) return false;
    if (q.user && e.user !== q.user && e.onBehalfOf !== q.user) return false;
    if (q.result && e.result !== q.result) return false;
    if (q.from !== undefined || q.to !== undefined) {
      const t = Date.parse(e.time);
      if (q.from !== undefined && t < q.from) return false;
      if (q.to !== undefined && t > q.to) return false;
    }
    return true;
  };
}

function filterKey(q: AuditQuery): string {
  return JSON.stringify([
    q.machine ?? null,
    q.machines ? [...q.machines].sort() : null,
    q.user ?? null,
    q.result ?? null,
    q.from ?? null,
    q.to ?? null,
  ]);
}

/**
 * The audit log: `<data>/audit.jsonl` and its rotated predecessors, one JSON object per line.
 *
 * - Writing (`writer: 'queue'`, the gateway): `append` puts the entry in memory at once (queries
 *   see it) and in a write queue; one file handle writes the queue in order, a batch at a time,
 *   and fsyncs a batch that holds a durable entry (`DURABLE_TYPES`) right after writing it.
 *   Before a write would pass `maxBytes` the file is fsynced, closed and rotated: `audit.jsonl`
 *   becomes `audit.1.jsonl`, `audit.1` becomes `audit.2` …, and `keep` files remain.
 * - Reading: the newest `indexSize` entries are loaded once at start, reading the files from
 *   their end backwards in chunks, and kept up to date by `append`; pages within them are
 *   answered from memory. Older pages, totals over older entries (then counted as entries leave
 *   the index, per filter) and the CSV export read the files backwards, streamed.
 * - A line that is not an entry (the last line torn by a crash) is skipped with one warning; the
 *   next write starts on a new line.
 * - Another process (`npm run user`) may append to `audit.jsonl` at any time: queries notice the
 *   file changed under them and load the index again.
 */
export class AuditLog {
  readonly file: string;
  private readonly writer: 'queue' | 'direct';
  private readonly maxBytes: number;
  private readonly keep: number;
  private readonly indexSize: number;
  private readonly fs: AuditFs;
  private readonly log: Logger;

  /** The newest entries, oldest first (written ones, then queued ones). */
  private index: Slot[] = [];
  /** The index holds every entry there is: nothing older on disk. */
  private complete = true;
  /** Bumped when the index is loaded again or files are deleted: scans under way start over. */
  private generation = 0;
  private readonly counters = new Map<string, Counter>();
  /** The index is to be loaded (again) from disk before the next read. */
  private stale = true;
  private loads = 0;

  /** `seg` of `audit.jsonl`; `audit.<n>.jsonl` is `seg - n`; +1 at each rotation. */
  private seg = 0;
  /** Size and inode of `audit.jsonl` as this process knows it (-1: no file). */
  private size = 0;
  private ino = -1;

  private fh: FileHandle | null = null;
  private readonly queue: Slot[] = [];
  private writeScheduled = false;
  private unsynced = false;
  private failing: unknown = null;
  private retryTimer: NodeJS.Timeout | null = null;
  private chain: Promise<unknown> = Promise.resolve();
  private closing: Promise<void> | null = null;
  private closed = false;
  /**
   * The data folder exists, or was made by this log: made once, never again (a folder removed
   * under a running gateway is reported, not silently made anew somewhere it no longer is).
   */
  private dirReady: boolean;

  constructor(
    readonly dataDir: string,
    opts: AuditLogOptions = {},
  ) {
    this.file = path.join(dataDir, AUDIT_FILE);
    this.writer = opts.writer ?? 'direct';
    this.maxBytes = Math.max(1, opts.maxBytes ?? DEFAULT_AUDIT_MAX_BYTES);
    this.keep = Math.max(1, Math.floor(opts.keep ?? DEFAULT_AUDIT_KEEP));
    this.indexSize = Math.max(1, Math.floor(opts.indexSize ?? DEFAULT_AUDIT_INDEX));
    this.fs = opts.fs ?? fsp;
    this.log = opts.log ?? loggerFromEnv();
    this.dirReady = existsSync(dataDir);
    if (this.writer === 'queue') {
      try {
        this.load();
      } catch (e) {
        this.log.error('cannot read the audit log', { file: this.file, error: String(e) });
        this.stale = false;
      }
    }
  }

  // ---------------------------------------------------------------- writing

  append(entry: Omit<AuditEntry, 'time'> & { time?: string }): AuditEntry {
    const { time, ...rest } = entry;
    const full = { time: time ?? new Date().toISOString(), ...rest } as AuditEntry;
    const slot: Slot = {
      e: full,
      line: Buffer.from(JSON.stringify(full) + '\n', 'utf8'),
      seg: null,
      offset: -1,
      durable: DURABLE_TYPES.has(full.type),
    };
    if (this.writer === 'direct' || this.closed) {
      this.writeDirect(slot);
      this.stale = true;
      return full;
    }
    this.push(slot);
    if (this.queue.length >= MAX_QUEUED) {
      const lost = this.queue.splice(0, this.queue.length - MAX_QUEUED + 1);
      this.log.error('audit entries lost: the audit log cannot be written', { lost: lost.length });
    }
    this.queue.push(slot);
    this.schedule();
    return full;
  }

  /**
   * Resolves when every entry appended before the call is written and fsynced (rejects when the
   * disk refuses them; they stay queued and are tried again).
   */
  flush(): Promise<void> {
    return this.serial(() => this.writeQueued(true));
  }

  /**
   * Shutdown: writes and fsyncs what is queued and closes the file. Entries appended later are
   * written directly (synchronously, fsynced), so nothing is lost to a late request.
   */
  close(): Promise<void> {
    if (this.writer === 'direct') return Promise.resolve();
    this.closing ??= this.serial(async () => {
      try {
        await this.writeQueued(true);
      } finally {
        if (this.retryTimer) clearTimeout(this.retryTimer);
        this.retryTimer = null;
        const fh = this.fh;
        this.fh = null;
        if (fh) await fh.close().catch(noop);
        this.closed = true;
        this.stale = true;
        for (const s of this.queue.splice(0)) {
          try {
            this.writeDirect(s);
          } catch (e) {
            this.log.error('could not write the audit log', { file: this.file, error: String(e) });
          }
        }
      }
    });
    return this.closing;
  }

  /** Runs `fn` after every file operation queued before it (writes, rotations, reloads). */
  private serial<T>(fn: () => Promise<T>): Promise<T> {
    const run = this.chain.then(fn);
    this.chain = run.catch(noop);
    return run;
  }

  private schedule(): void {
    if (this.writeScheduled) return;
    this.writeScheduled = true;
    void this.serial(async () => {
      this.writeScheduled = false;
      await this.writeQueued(false).catch(noop);
    });
  }

  private push(slot: Slot): void {
    this.index.push(slot);
    if (this.index.length <= this.indexSize) return;
    // The oldest entry leaves memory: counts of older entries take it in.
    const old = this.index.shift();
    this.complete = false;
    if (old) for (const c of this.counters.values()) if (c.match(old.e)) c.n++;
  }

  /** Writes the queue in order; fsyncs batches with durable entries (all of them with `sync`). */
  private async writeQueued(sync: boolean): Promise<void> {
    try {
      while (this.queue.length) {
        const fh = await this.handle();
        const room = this.maxBytes - this.size;
        const first = this.queue[0]?.line?.length ?? 0;
        if (this.size > 0 && first > room) {
          await this.rotate();
          continue;
        }
        const batch: Slot[] = [];
        let bytes = 0;
        let durable = false;
        for (const s of this.queue) {
          const n = s.line?.length ?? 0;
          if (batch.length && (bytes + n > room || bytes + n > MAX_BATCH_BYTES)) break;
          batch.push(s);
          bytes += n;
          durable ||= s.durable;
        }
        await writeAll(
          fh,
          batch.length === 1
            ? (batch[0]?.line ?? NEWLINE)
            : Buffer.concat(batch.map((s) => s.line ?? NEWLINE)),
        );
        this.queue.splice(0, batch.length);
        for (const s of batch) {
          s.seg = this.seg;
          s.offset = this.size;
          this.size += s.line?.length ?? 0;
          s.line = null;
        }
        this.unsynced = true;
        if (durable) await this.sync(fh);
      }
      if (sync && this.unsynced && this.fh) await this.sync(this.fh);
      if (this.failing) this.log.info('the audit log is written again', { file: this.file });
      this.failing = null;
    } catch (e) {
      this.failed(e);
      throw e;
    }
  }

  private async sync(fh: FileHandle): Promise<void> {
    await fh.sync();
    this.unsynced = false;
  }

  /** A write failed: the entries stay queued, the file is opened again for the next try. */
  private failed(e: unknown): void {
    if (!this.failing)
      this.log.error('could not write the audit log: retrying', {
        file: this.file,
        error: String(e),
        waiting: this.queue.length,
      });
    this.failing = e;
    const fh = this.fh;
    this.fh = null;
    if (fh) void fh.close().catch(noop);
    if (!this.retryTimer && !this.closing) {
      this.retryTimer = setTimeout(() => {
        this.retryTimer = null;
        if (this.queue.length) this.schedule();
      }, RETRY_MS);
      this.retryTimer.unref();
    }
  }

  /** The handle `audit.jsonl` is appended by; a torn last line is ended first. */
  private async handle(): Promise<FileHandle> {
    if (this.fh) return this.fh;
    if (!this.dirReady) {
      await this.fs.mkdir(this.dataDir, { recursive: true });
      this.dirReady = true;
    }
    const fh = await this.fs.open(this.file, 'a+', 0o600);
    try {
      const st = await fh.stat();
      // Someone else wrote to it (`npm run user`) or replaced it since we last knew it.
      const changed = st.size !== this.size || (this.ino !== -1 && st.ino !== this.ino);
      let size = st.size;
      if (size > 0) {
        const last = Buffer.alloc(1);
        await fh.read(last, 0, 1, size - 1);
        if (last[0] !== 0x0a) {
          await writeAll(fh, NEWLINE);
          size++;
        }
      }
      if (changed) this.load();
      this.size = size;
      this.ino = st.ino;
    } catch (e) {
      await fh.close().catch(noop);
      throw e;
    }
    this.fh = fh;
    return fh;
  }

  private async rotate(): Promise<void> {
    const fh = this.fh;
    if (fh) {
      if (this.unsynced) await this.sync(fh);
      this.fh = null;
      await fh.close();
    }
    const at = (n: number): string => path.join(this.dataDir, auditFileName(n));
    let deleted = false;
    const unlink = async (file: string): Promise<void> => {
      try {
        await this.fs.unlink(file);
        deleted = true;
      } catch (e) {
        if (!isNotFound(e)) throw e;
      }
    };
    const rename = async (from: string, to: string): Promise<void> => {
      try {
        await this.fs.rename(from, to);
      } catch (e) {
        if (!isNotFound(e)) throw e;
      }
    };
    // The oldest kept file goes, and any beyond it (a smaller `keep` than before).
    for (const name of await this.fs.readdir(this.dataDir)) {
      const m = /^audit\.(\d+)\.jsonl$/.exec(name);
      if (m && Number(m[1]) >= this.keep - 1) await unlink(at(Number(m[1])));
    }
    for (let n = this.keep - 2; n >= 0; n--) await rename(at(n), at(n + 1));
    if (this.keep === 1) await unlink(at(0));
    this.seg++;
    this.size = 0;
    this.ino = -1;
    if (deleted) this.dropped(this.seg - this.keep);
    await this.syncDir();
  }

  /** Files with `seg` up to `last` are gone: so are their entries in memory and older counts. */
  private dropped(last: number): void {
    let k = 0;
    while (k < this.index.length && this.index[k]?.seg !== null && (this.index[k]?.seg ?? 0) <= last) k++;
    if (k > 0) {
      this.index.splice(0, k);
      this.complete = true;
    }
    const first = this.index[0];
    if (first && first.seg === last + 1 && first.offset === 0) this.complete = true;
    this.counters.clear();
    this.generation++;
  }

  /** The renames themselves made durable (where the system can: not on Windows). */
  private async syncDir(): Promise<void> {
    let dir: FileHandle | null = null;
    try {
      dir = await this.fs.open(this.dataDir, 'r');
      await dir.sync();
    } catch {
      // not possible here
    } finally {
      await dir?.close().catch(noop);
    }
  }

  /** `npm run user`, and anything appended after `close()`: written and fsynced before returning. */
  private writeDirect(slot: Slot): void {
    if (!slot.line) return;
    if (!this.dirReady) {
      mkdirSync(this.dataDir, { recursive: true });
      this.dirReady = true;
    }
    const fd = openSync(this.file, 'a+', 0o600);
    try {
      const size = fstatSync(fd).size;
      if (size > 0) {
        const last = Buffer.alloc(1);
        readSync(fd, last, 0, 1, size - 1);
        if (last[0] !== 0x0a) writeAllSync(fd, NEWLINE);
      }
      writeAllSync(fd, slot.line);
      fsyncSync(fd);
    } finally {
      closeSync(fd);
    }
  }

  // ---------------------------------------------------------------- loading

  /** Files there are, newest first: `audit.jsonl`, `audit.1.jsonl` … up to the first missing. */
  private filesSync(): Array<{ fd: number; seg: number; size: number; ino: number }> {
    const out: Array<{ fd: number; seg: number; size: number; ino: number }> = [];
    for (let n = 0; ; n++) {
      let fd: number;
      try {
        fd = openSync(path.join(this.dataDir, auditFileName(n)), 'r');
      } catch (e) {
        if (isNotFound(e)) break;
        for (const f of out) closeSync(f.fd);
        throw e;
      }
      const st = fstatSync(fd);
      out.push({ fd, seg: this.seg - n, size: st.size, ino: st.ino });
    }
    return out;
  }

  /**
   * (Re)loads the newest `indexSize` entries, reading from the end of the files backwards (never
   * a whole file at once); entries not written yet stay. Called at start, and when another
   * process changed the file (in the write queue: no write is under way).
   */
  private load(): void {
    const waiting = this.index.filter((s) => s.seg === null);
    const found: Slot[] = [];
    let complete = true;
    let torn = false;
    let bad = 0;
    const files = this.filesSync();
    try {
      this.size = files[0]?.size ?? 0;
      this.ino = files[0]?.ino ?? -1;
      for (const [i, f] of files.entries()) {
        const more = readLinesBackSync(f.fd, f.size, (buf, start, end) => {
          const e = parseLine(buf);
          if (e === 'blank') return true;
          if (e === null) {
            if (i === 0 && end === f.size) torn = true;
            else bad++;
            return true;
          }
          found.push({ e, line: null, seg: f.seg, offset: start, durable: false });
          return found.length < this.indexSize;
        });
        if (!more) {
          complete = false;
          break;
        }
      }
    } finally {
      for (const f of files) closeSync(f.fd);
    }
    found.reverse();
    this.index = found;
    this.complete = complete;
    this.counters.clear();
    this.generation++;
    this.stale = false;
    for (const s of waiting) this.push(s);
    if (this.loads++ === 0) {
      if (torn)
        this.log.warn('the last line of the audit log is incomplete (written during a crash?): skipped', {
          file: this.file,
        });
      if (bad)
        this.log.warn(`${bad} ${bad === 1 ? 'line' : 'lines'} of the audit log are not entries: skipped`, {
          file: this.file,
        });
    }
  }

  /** Direct mode (and after `close()`): load again when the file changed since. */
  private freshSync(): void {
    if (this.writer === 'queue' && !this.closed) return;
    if (!this.stale) {
      let size = 0;
      let ino = -1;
      try {
        const st = statSync(this.file);
        size = st.size;
        ino = st.ino;
      } catch (e) {
        if (!isNotFound(e)) throw e;
      }
      if (size === this.size && ino === this.ino) return;
    }
    this.load();
  }

  /** Before a query: the file as this process knows it, or loaded again (another process wrote). */
  private async fresh(): Promise<void> {
    if (this.writer === 'direct' || this.closed) {
      this.freshSync();
      return;
    }
    await this.serial(async () => {
      let size = 0;
      let ino = -1;
      try {
        const st = await this.fs.stat(this.file);
        size = st.size;
        ino = st.ino;
      } catch (e) {
        if (!isNotFound(e)) throw e;
      }
      if (size === this.size && (ino === this.ino || this.ino === -1)) return;
      const fh = this.fh;
      this.fh = null;
      if (fh) await fh.close().catch(noop);
      this.load();
    });
  }

  // ---------------------------------------------------------------- reading

  /**
   * Every entry, oldest first, synchronously: for tests and tools. In the gateway it is what
   * this process knows (the index, or the files read up to what it wrote, then the queue).
   */
  all(): AuditEntry[] {
    this.freshSync();
    if (this.complete) return this.index.map((s) => s.e);
    const out: AuditEntry[] = [];
    const files = this.filesSync();
    try {
      for (const [i, f] of files.entries()) {
        readLinesBackSync(f.fd, i === 0 ? Math.min(f.size, this.size) : f.size, (buf) => {
          const e = parseLine(buf);
          if (e && e !== 'blank') out.push(e);
          return true;
        });
      }
    } finally {
      for (const f of files) closeSync(f.fd);
    }
    out.reverse();
    for (const s of this.index) if (s.seg === null) out.push(s.e);
    return out;
  }

  /** Filtered, newest first: every matching entry (the CSV export). */
  async filtered(q: AuditQuery): Promise<AuditEntry[]> {
    return (await this.search(q, 0, Number.POSITIVE_INFINITY, false)).entries;
  }

  /** A page of the filtered entries, newest first, and how many match in all. */
  async query(q: AuditQuery): Promise<{ entries: AuditEntry[]; total: number }> {
    const offset = Math.max(0, q.offset ?? 0);
    const limit = Math.min(1000, Math.max(1, q.limit ?? 50));
    return this.search(q, offset, limit, true);
  }

  private async search(
    q: AuditQuery,
    skip: number,
    take: number,
    wantTotal: boolean,
  ): Promise<{ entries: AuditEntry[]; total: number }> {
    const match = auditMatcher(q);
    const key = filterKey(q);
    for (let attempt = 0; ; attempt++) {
      await this.fresh();
      // Older entries end where the oldest one in memory starts: it must be on disk.
      if (!this.complete && this.index[0]?.seg === null) await this.flush();
      // From here to the scan's start nothing awaits: memory and the scan see the same moment.
      const entries: AuditEntry[] = [];
      let n = 0;
      for (let i = this.index.length - 1; i >= 0; i--) {
        const e = this.index[i]?.e;
        if (!e || !match(e)) continue;
        if (n >= skip && entries.length < take) entries.push(e);
        n++;
      }
      const oldest = this.index[0];
      if (this.complete || !oldest || oldest.seg === null) return { entries, total: n };
      const counted = this.counters.get(key);
      const known = counted?.ready ? counted.n : null;
      if (entries.length >= take && known !== null) return { entries, total: n + known };
      let counter: Counter | null = null;
      if (wantTotal && known === null) {
        counter = { match, n: 0, ready: false };
        this.counters.delete(key);
        this.counters.set(key, counter);
        if (this.counters.size > MAX_COUNTERS) {
          const first = this.counters.keys().next().value;
          if (first !== undefined) this.counters.delete(first);
        }
      }
      const older = await this.scanOlder(
        { seg: oldest.seg, offset: oldest.offset },
        this.generation,
        match,
        Math.max(0, skip - n),
        take - entries.length,
        counter !== null,
      );
      if (older === null) {
        if (attempt < 3) continue;
        throw new Error('the audit log kept changing while it was read');
      }
      entries.push(...older.entries);
      if (counter) {
        counter.n += older.matched;
        counter.ready = true;
        return { entries, total: n + older.matched };
      }
      return { entries, total: n + (known ?? older.matched) };
    }
  }

  /**
   * Entries before `from` (the oldest one in memory), newest first, read backwards from the
   * files. Null when files were reloaded or deleted meanwhile (the caller starts again).
   */
  private async scanOlder(
    from: { seg: number; offset: number },
    generation: number,
    match: (e: AuditEntry) => boolean,
    skip: number,
    take: number,
    countAll: boolean,
  ): Promise<{ entries: AuditEntry[]; matched: number } | null> {
    // Opened in the write queue: no rotation renames files meanwhile; open handles survive later ones.
    const files = await this.serial(async () => {
      if (this.generation !== generation) return null;
      const out: Array<{ fh: FileHandle; end: number }> = [];
      try {
        for (let seg = from.seg; ; seg--) {
          let fh: FileHandle;
          try {
            fh = await this.fs.open(path.join(this.dataDir, auditFileName(this.seg - seg)), 'r');
          } catch (e) {
            if (isNotFound(e)) break;
            throw e;
          }
          out.push({ fh, end: 0 });
          const f = out[out.length - 1];
          if (f) f.end = seg === from.seg ? from.offset : (await fh.stat()).size;
        }
      } catch (e) {
        for (const f of out) await f.fh.close().catch(noop);
        throw e;
      }
      return out;
    });
    if (!files) return null;
    const entries: AuditEntry[] = [];
    let matched = 0;
    try {
      for (const f of files) {
        const more = await readLinesBack(f.fh, f.end, (buf) => {
          const e = parseLine(buf);
          if (!e || e === 'blank' || !match(e)) return true;
          if (matched >= skip && entries.length < take) entries.push(e);
          matched++;
          return countAll || entries.length < take;
        });
        if (!more) break;
      }
    } finally {
      for (const f of files) await f.fh.close().catch(noop);
    }
    return this.generation === generation ? { entries, matched } : null;
  }
}

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
