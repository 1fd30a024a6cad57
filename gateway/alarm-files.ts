import {
  closeSync,
  fsyncSync,
  mkdirSync,
  openSync,
  readFileSync,
  renameSync,
  truncateSync,
  writeFileSync,
  writeSync,
} from 'node:fs';
import { open, rename } from 'node:fs/promises';
import { join } from 'node:path';
import { z } from 'zod';
import { alarmRecordSchema, type AlarmRecord } from '../src/fleet/alarm-record';
import type { Logger } from './log';

/**
 * The alarm centre's list on disk (alarms.ts): `alarms.journal`, one JSON line per record changed
 * (written and fsynced before the change is announced), and the snapshot `alarms.json` (written to
 * a temporary file, fsynced and renamed 200 ms later), which says which journal lines it holds;
 * later lines are replayed at start and the journal is emptied once a snapshot holds all of it.
 */

/** What the snapshot holds: the centre's list as it is when the snapshot is written. */
export interface AlarmList {
  seq: number;
  records: AlarmRecord[];
}

const fileSchema = z.object({
  version: z.literal(1),
  seq: z.number().int().nonnegative(),
  /** The last journal line this snapshot holds (absent: none). */
  journal: z.number().int().nonnegative().optional(),
  records: z.array(alarmRecordSchema),
});
const journalLineSchema = z.object({ v: z.number().int().positive(), r: alarmRecordSchema });

export class AlarmFiles {
  private readonly file: string | null;
  private readonly journalFile: string | null;
  /** The last journal line written (every change of a record is one). */
  private journalSeq = 0;
  private journalDirSynced = false;
  private writeTimer: ReturnType<typeof setTimeout> | null = null;
  private writing: Promise<void> = Promise.resolve();

  /** `dataDir` null: nothing on disk (tests). `list`: the centre's list now (for a snapshot). */
  constructor(
    dataDir: string | null,
    private readonly log: Logger,
    private readonly now: () => number,
    private readonly list: () => AlarmList,
  ) {
    this.file = dataDir ? join(dataDir, 'alarms.json') : null;
    this.journalFile = dataDir ? join(dataDir, 'alarms.journal') : null;
  }

  /** The list at start: the snapshot, then the journal lines after it (`replayed` of them). */
  load(): AlarmList & { replayed: number } {
    const list = this.loadSnapshot();
    const replayed = this.replayJournal(list);
    if (replayed > 0) this.log.info('alarm records recovered from the journal', { count: replayed });
    return { ...list, replayed };
  }

  /** Journal lines after the snapshot: each the record as it was after a change (by id). */
  private replayJournal(list: AlarmList): number {
    if (!this.journalFile) return 0;
    let text: string;
    try {
      text = readFileSync(this.journalFile, 'utf8');
    } catch {
      return 0; // no journal
    }
    const after = this.journalSeq;
    let replayed = 0;
    for (const line of text.split('\n')) {
      if (!line.trim()) continue;
      let parsed: z.infer<typeof journalLineSchema> | null = null;
      try {
        const r = journalLineSchema.safeParse(JSON.parse(line));
        if (r.success) parsed = r.data;
      } catch {
        parsed = null; // a line cut short by a crash: the ones before it stand
      }
      if (!parsed) continue;
      this.journalSeq = Math.max(this.journalSeq, parsed.v);
      if (parsed.v <= after) continue;
      const rec = parsed.r;
      const i = list.records.findIndex((x) => x.id === rec.id);
      if (i >= 0) list.records[i] = rec;
      else list.records.push(rec);
      list.seq = Math.max(list.seq, Number(rec.id) || 0);
      replayed++;
    }
    return replayed;
  }

  private loadSnapshot(): AlarmList {
    const empty: AlarmList = { seq: 0, records: [] };
    if (!this.file) return empty;
    let text: string;
    try {
      text = readFileSync(this.file, 'utf8');
    } catch {
      return empty; // no file yet
    }
    let parsed: z.infer<typeof fileSchema> | null = null;
    try {
      const r = fileSchema.safeParse(JSON.parse(text));
      if (r.success) parsed = r.data;
    } catch {
      parsed = null;
    }
    if (!parsed) {
      // Never lose it: set aside for a person to look at, and start a new list.
      const aside = `${this.file}.unreadable-${this.now()}`;
      try {
        renameSync(this.file, aside);
      } catch {
        /* the next write replaces it */
      }
      this.log.error('the alarm list could not be read; it was set aside and a new one started', {
        file: aside,
      });
      return empty;
    }
    this.journalSeq = parsed.journal ?? 0;
    return {
      records: parsed.records,
      seq: Math.max(parsed.seq, ...parsed.records.map((r) => Number(r.id) || 0)),
    };
  }

  /**
   * Journal lines for the changed records, written and fsynced (one fsync for all). A journal
   * that cannot be written is logged (the caller announces the alarm anyway: never hidden).
   */
  append(records: AlarmRecord[]): void {
    const file = this.journalFile;
    if (!file) return;
    const lines = records.map((r) => `${JSON.stringify({ v: ++this.journalSeq, r })}\n`).join('');
    let fd: number | null = null;
    try {
      mkdirSync(join(file, '..'), { recursive: true });
      fd = openSync(file, 'a', 0o600);
      writeSync(fd, lines);
      fsyncSync(fd);
    } catch (e) {
      this.log.error('cannot write the alarm journal: an alarm may be lost if the server stops now', {
        file,
        error: String(e),
      });
    } finally {
      if (fd !== null) closeSync(fd);
    }
    if (!this.journalDirSynced) {
      // The journal's own directory entry, once: a new file survives a power cut too.
      this.journalDirSynced = true;
      syncDir(join(file, '..'));
    }
  }

  private serialise(): string {
    const { seq, records } = this.list();
    return JSON.stringify({ version: 1, seq, journal: this.journalSeq, records });
  }

  /** After a snapshot holding journal line `upTo` is in place: the journal is emptied when it holds nothing newer. */
  private journalCovered(upTo: number): void {
    if (!this.journalFile || this.journalSeq !== upTo) return;
    try {
      truncateSync(this.journalFile, 0);
    } catch {
      /* no journal yet */
    }
  }

  /** A snapshot within 200 ms (one for all the changes until then). */
  scheduleWrite(): void {
    if (!this.file || this.writeTimer) return;
    this.writeTimer = setTimeout(() => {
      this.writeTimer = null;
      this.writing = this.writing.then(() => this.writeNow());
    }, 200);
    this.writeTimer.unref?.();
  }

  /** Written to a temporary file, fsynced and renamed: a crash leaves the old list or the new one. */
  private async writeNow(): Promise<void> {
    const file = this.file;
    if (!file) return;
    const tmp = `${file}.tmp`;
    try {
      mkdirSync(join(file, '..'), { recursive: true });
      // The list and the journal line it holds, taken together.
      const text = this.serialise();
      const upTo = this.journalSeq;
      const fh = await open(tmp, 'w', 0o600);
      try {
        await fh.writeFile(text);
        await fh.sync();
      } finally {
        await fh.close();
      }
      await rename(tmp, file);
      syncDir(join(file, '..'));
      this.journalCovered(upTo);
    } catch (e) {
      this.log.error('cannot write the alarm list', { file, error: String(e) });
    }
  }

  /** Writes what is pending now (shutdown). */
  async close(): Promise<void> {
    if (this.writeTimer) {
      clearTimeout(this.writeTimer);
      this.writeTimer = null;
      this.writing = this.writing.then(() => this.writeNow());
    }
    await this.writing;
  }

  /** For a synchronous shutdown path: writes at once. */
  flushSync(): void {
    if (!this.file || !this.writeTimer) return;
    clearTimeout(this.writeTimer);
    this.writeTimer = null;
    const tmp = `${this.file}.tmp`;
    const upTo = this.journalSeq;
    writeFileSync(tmp, this.serialise(), { mode: 0o600 });
    renameSync(tmp, this.file);
    this.journalCovered(upTo);
  }
}

/** fsync of a directory (its entries: a renamed or new file); not every platform allows it. */
function syncDir(dir: string): void {
  let fd: number | null = null;
  try {
    fd = openSync(dir, 'r');
    fsyncSync(fd);
  } catch {
    /* Windows cannot open a directory: the rename is as durable as the platform makes it */
  } finally {
    if (fd !== null) closeSync(fd);
  }
}
