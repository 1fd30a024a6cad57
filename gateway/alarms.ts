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
import type { WatchAlarm, WatchSummary } from '../src/fleet/contract';
import { SEVERITY_RANK, type AlarmSeverity } from '../src/fleet/types';
import type { Logger } from './log';
import { SettingsStore } from './settings';
import { Webhook } from './webhook';

/**
 * The alarm centre: every alarm and message of every machine, as the gateway's watch sees them
 * (watch.ts), whether or not a page is open. A record opens when the controller raises an alarm,
 * clears itself when the controller no longer reports it (and stays in the history), and is
 * acknowledged by a person (who, when). A machine that goes offline during a job is an alarm of
 * its own. Kept in `alarms.json` in the data folder (written atomically), bounded.
 *
 * Durable before announced: every change is appended to `alarms.journal` (one JSON line per
 * record changed, written and fsynced synchronously) before anyone is told of it: the pages (the
 * list is read from memory only after this synchronous step), the webhook and the audit (the
 * `onChange` listener), the log and the audit's alarm line (the watch reports after it observes).
 * A SIGKILL right after the announcement keeps the record. `alarms.json` is the snapshot (written
 * to a temporary file, fsynced and renamed shortly after); it says which journal lines it holds
 * (`journal`), later lines are replayed at start, and the journal is emptied once a snapshot
 * holds all of it.
 */

export type { AlarmRecord };

export interface AlarmMachine {
  id: string;
  name: string;
  kind: string;
}

export type AlarmState = 'active' | 'unacknowledged' | 'cleared' | 'all';

export interface AlarmQuery {
  /** The machines the asker may see (null: all). */
  machines: readonly string[] | null;
  machine?: string;
  family?: string;
  severity?: AlarmSeverity;
  state?: AlarmState;
  limit?: number;
}

export type AlarmEvent = 'alarm.raised' | 'alarm.cleared' | 'alarm.acknowledged';

export interface AlarmCentreOptions {
  /** The data folder (`alarms.json`); null keeps the list in memory only (tests). */
  dataDir: string | null;
  log: Logger;
  now?: () => number;
  /** Each change of a record (the webhook, the audit log). */
  onChange?: (event: AlarmEvent, record: AlarmRecord) => void;
  /** Records kept at most (default 5000; open or unacknowledged critical ones are kept first). */
  maxRecords?: number;
  /** Cleared records older than this are pruned (default 90 days). */
  keepMs?: number;
}

export const OFFLINE_KEY = 'offline-during-job';
const MAX_TEXT = 500;

const fileSchema = z.object({
  version: z.literal(1),
  seq: z.number().int().nonnegative(),
  /** The last journal line this snapshot holds (absent: none). */
  journal: z.number().int().nonnegative().optional(),
  records: z.array(alarmRecordSchema),
});
const journalLineSchema = z.object({ v: z.number().int().positive(), r: alarmRecordSchema });

/** Newest and most severe first: severity, then active before cleared, then newest. */
export function compareAlarms(a: AlarmRecord, b: AlarmRecord): number {
  return (
    SEVERITY_RANK[b.severity] - SEVERITY_RANK[a.severity] ||
    Number(a.clearedAt !== null) - Number(b.clearedAt !== null) ||
    b.since - a.since
  );
}

/** One line for the log, the webhook's `text`, a notification. */
export function alarmLine(r: AlarmRecord): string {
  return `${r.machineName}: ${r.severity} — ${r.text}`;
}

export class AlarmCentre {
  private records: AlarmRecord[] = [];
  private seq = 0;
  /** Bumped on every change: a page that has this version has everything. */
  version = 0;
  private readonly file: string | null;
  private readonly journalFile: string | null;
  /** The last journal line written (every change of a record is one). */
  private journalSeq = 0;
  /** Records changed and events to announce since the last `commit()`. */
  private readonly dirty = new Set<AlarmRecord>();
  private readonly pending: Array<[AlarmEvent, AlarmRecord]> = [];
  private readonly now: () => number;
  private writeTimer: ReturnType<typeof setTimeout> | null = null;
  private writing: Promise<void> = Promise.resolve();

  constructor(private readonly opts: AlarmCentreOptions) {
    this.file = opts.dataDir ? join(opts.dataDir, 'alarms.json') : null;
    this.journalFile = opts.dataDir ? join(opts.dataDir, 'alarms.journal') : null;
    this.now = opts.now ?? Date.now;
    this.load();
  }

  private load(): void {
    this.loadSnapshot();
    this.replayJournal();
  }

  /** Journal lines after the snapshot: each the record as it was after a change (by id). */
  private replayJournal(): void {
    if (!this.journalFile) return;
    let text: string;
    try {
      text = readFileSync(this.journalFile, 'utf8');
    } catch {
      return; // no journal
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
      const i = this.records.findIndex((x) => x.id === rec.id);
      if (i >= 0) this.records[i] = rec;
      else this.records.push(rec);
      this.seq = Math.max(this.seq, Number(rec.id) || 0);
      replayed++;
    }
    if (replayed > 0) {
      this.opts.log.info('alarm records recovered from the journal', { count: replayed });
      this.version++;
      this.scheduleWrite();
    }
  }

  private loadSnapshot(): void {
    if (!this.file) return;
    let text: string;
    try {
      text = readFileSync(this.file, 'utf8');
    } catch {
      return; // no file yet
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
      this.opts.log.error('the alarm list could not be read; it was set aside and a new one started', {
        file: aside,
      });
      return;
    }
    this.records = parsed.records;
    this.seq = Math.max(parsed.seq, ...this.records.map((r) => Number(r.id) || 0));
    this.journalSeq = parsed.journal ?? 0;
  }

  /** What the watch learnt about a machine: open, update and clear its records. */
  observe(m: AlarmMachine, prev: WatchSummary, next: WatchSummary): void {
    const t = this.now();
    let changed = false;
    // A machine that goes offline during a job.
    if (next.state === 'offline' && (prev.state === 'running' || prev.state === 'paused')) {
      const job = prev.job ?? next.job;
      changed =
        this.raise(m, {
          key: OFFLINE_KEY,
          severity: 'warning',
          text: `Went offline while ${prev.state === 'running' ? 'running' : 'paused in'} a job${job ? ` (${job})` : ''}: the console cannot see what the machine does.`,
        }) || changed;
    } else if (next.state !== 'offline' && next.state !== 'unknown') {
      changed = this.clear(m.id, (r) => r.key === OFFLINE_KEY, t) || changed;
    }
    // The family's alarms: only when it said (an offline machine keeps its last known).
    if (next.alarms && next.state !== 'offline') {
      const active = new Set<string>();
      const events = new Set(next.raised ?? []);
      for (const a of next.alarms) {
        active.add(a.key);
        // Raised again as an event after a person acknowledged it: a new alarm, not the old one.
        const open = events.has(a.key) ? this.openRecord(m.id, a.key) : undefined;
        if (open && open.ackAt !== null) changed = this.clear(m.id, (r) => r === open, t) || changed;
        changed = this.raise(m, a) || changed;
      }
      changed = this.clear(m.id, (r) => r.key !== OFFLINE_KEY && !active.has(r.key), t) || changed;
    }
    if (changed) this.changed();
    this.commit();
  }

  private openRecord(machine: string, key: string): AlarmRecord | undefined {
    return this.records.find((r) => r.machine === machine && r.key === key && r.clearedAt === null);
  }

  /** Opens a record (or updates the open one's words). True when something changed. */
  private raise(m: AlarmMachine, a: WatchAlarm): boolean {
    const text = a.text.slice(0, MAX_TEXT);
    const open = this.openRecord(m.id, a.key);
    if (open) {
      if (open.text === text && open.severity === a.severity) return false;
      open.text = text;
      // Never quieter while it lasts: a critical alarm stays critical.
      if (SEVERITY_RANK[a.severity] > SEVERITY_RANK[open.severity]) open.severity = a.severity;
      this.dirty.add(open);
      return true;
    }
    const t = this.now();
    const r: AlarmRecord = {
      id: String(++this.seq),
      machine: m.id,
      machineName: m.name,
      family: m.kind,
      key: a.key.slice(0, 200),
      severity: a.severity,
      text,
      blocking: a.blocking === true,
      since: t,
      clearedAt: null,
      ackBy: null,
      ackAt: null,
    };
    this.records.push(r);
    // The log line and the audit entry are the watch's (gateway.ts): one each, not two. Announced
    // by `commit()`, once the record is in the journal.
    this.dirty.add(r);
    this.pending.push(['alarm.raised', r]);
    return true;
  }

  private clear(machine: string, which: (r: AlarmRecord) => boolean, t: number): boolean {
    let changed = false;
    for (const r of this.records) {
      if (r.machine !== machine || r.clearedAt !== null || !which(r)) continue;
      r.clearedAt = t;
      changed = true;
      this.dirty.add(r);
      this.pending.push(['alarm.cleared', r]);
    }
    return changed;
  }

  /** Acknowledges a record by id: the record, 'already' (someone did), or null (no such record). */
  acknowledge(id: string, by: string): AlarmRecord | 'already' | null {
    const r = this.records.find((x) => x.id === id);
    if (!r) return null;
    if (r.ackAt !== null) return 'already';
    r.ackBy = by.slice(0, 200);
    r.ackAt = this.now();
    this.dirty.add(r);
    this.pending.push(['alarm.acknowledged', r]);
    this.changed();
    this.commit();
    return r;
  }

  /**
   * Makes the changes since the last commit durable (journal lines, written and fsynced, one
   * fsync for all), then announces them (`onChange`: the webhook, the audit). Synchronous: no
   * page can read a record before it is on disk. A journal that cannot be written is logged and
   * the alarm announced anyway (never hidden).
   */
  private commit(): void {
    if (this.dirty.size > 0) {
      const records = [...this.dirty];
      this.dirty.clear();
      this.appendJournal(records);
    }
    const events = this.pending.splice(0);
    for (const [event, r] of events) this.opts.onChange?.(event, r);
  }

  private appendJournal(records: AlarmRecord[]): void {
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
      this.opts.log.error('cannot write the alarm journal: an alarm may be lost if the server stops now', {
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
  private journalDirSynced = false;

  /**
   * Acknowledges a machine's alarm by its key: the open record of that key (an alarm the watch
   * has seen and recorded). Nothing is acknowledged in advance: with no open record of that key,
   * null (the caller answers 404), and nothing is kept.
   */
  acknowledgeKey(machine: string, key: string, by: string): AlarmRecord | 'already' | null {
    const r = this.openRecord(machine, key);
    return r ? this.acknowledge(r.id, by) : null;
  }

  /** The open record of a machine's alarm key, if any. */
  open(machine: string, key: string): AlarmRecord | undefined {
    return this.openRecord(machine, key);
  }

  get(id: string): AlarmRecord | undefined {
    return this.records.find((r) => r.id === id);
  }

  /** The records a person may see, filtered, newest and most severe first. */
  query(q: AlarmQuery): AlarmRecord[] {
    const may = q.machines ? new Set(q.machines) : null;
    const state = q.state ?? 'all';
    const out = this.records.filter(
      (r) =>
        (!may || may.has(r.machine)) &&
        (!q.machine || r.machine === q.machine) &&
        (!q.family || r.family === q.family) &&
        (!q.severity || r.severity === q.severity) &&
        (state === 'all' ||
          (state === 'active' && r.clearedAt === null) ||
          (state === 'cleared' && r.clearedAt !== null) ||
          (state === 'unacknowledged' && r.ackAt === null)),
    );
    out.sort(compareAlarms);
    return out.slice(0, q.limit ?? 500);
  }

  private changed(): void {
    this.version++;
    this.prune();
    this.scheduleWrite();
  }

  /** Bounded: cleared records past `keepMs`, then the oldest acknowledged-and-cleared ones. */
  private prune(): void {
    const max = this.opts.maxRecords ?? 5000;
    const keepMs = this.opts.keepMs ?? 90 * 86_400_000;
    const t = this.now();
    this.records = this.records.filter((r) => r.clearedAt === null || t - r.clearedAt <= keepMs);
    if (this.records.length <= max) return;
    const spare = (r: AlarmRecord) => r.clearedAt === null || (r.ackAt === null && r.severity === 'critical');
    const drop = new Set(
      this.records
        .filter((r) => !spare(r))
        .sort((a, b) => a.since - b.since)
        .slice(0, this.records.length - max)
        .map((r) => r.id),
    );
    this.records = this.records.filter((r) => !drop.has(r.id));
    // Still too many (all open): the oldest go.
    if (this.records.length > max) this.records = this.records.slice(this.records.length - max);
  }

  private serialise(): string {
    return JSON.stringify({ version: 1, seq: this.seq, journal: this.journalSeq, records: this.records });
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

  private scheduleWrite(): void {
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
      this.opts.log.error('cannot write the alarm list', { file, error: String(e) });
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

/** What the webhook receives: the event, a line for chat receivers (`text`), the record. */
export function webhookPayload(event: AlarmEvent | 'test', r: AlarmRecord): Record<string, unknown> {
  const words = {
    'alarm.raised': 'Alarm',
    'alarm.cleared': 'Cleared',
    'alarm.acknowledged': 'Acknowledged',
    test: 'Test',
  };
  const by = event === 'alarm.acknowledged' && r.ackBy ? ` (by ${r.ackBy})` : '';
  return {
    source: 'shopdeck',
    event,
    text: `${words[event]}: ${alarmLine(r)}${by}`,
    alarm: { ...r, since: new Date(r.since).toISOString(), clearedAt: iso(r.clearedAt), ackAt: iso(r.ackAt) },
  };
}

function iso(t: number | null): string | null {
  return t === null ? null : new Date(t).toISOString();
}

/** The alarm centre, the server settings and the webhook that sends alarms on, wired together. */
export function createAlarmStores(o: {
  dataDir: string;
  env: NodeJS.ProcessEnv;
  log: Logger;
  now: () => number;
  /** The machines file: the webhook never reaches a machine's host. */
  config?: { machines: ReadonlyArray<{ url: URL | null; wsUrl: URL | null }> };
}): { alarms: AlarmCentre; settings: SettingsStore; webhook: Webhook } {
  const settings = new SettingsStore(o.dataDir, o.env, o.log);
  const webhook = new Webhook({
    url: () => settings.webhookUrl(),
    log: o.log,
    allowedHosts: () => settings.webhookAllowHosts(),
    machineHosts: () =>
      (o.config?.machines ?? []).flatMap(
        (m) => [m.url?.hostname, m.wsUrl?.hostname].filter((h) => !!h) as string[],
      ),
  });
  const alarms = new AlarmCentre({
    dataDir: o.dataDir,
    log: o.log,
    now: o.now,
    onChange: (event, r) => webhook.send(`${event} ${r.id}`, webhookPayload(event, r)),
  });
  return { alarms, settings, webhook };
}
