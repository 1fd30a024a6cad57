import type { AlarmRecord } from '../src/fleet/alarm-record';
import type { WatchAlarm, WatchSummary } from '../src/fleet/contract';
import { SEVERITY_RANK, type AlarmSeverity } from '../src/fleet/types';
import { AlarmFiles } from './alarm-files';
import type { Logger } from './log';
import { SettingsStore } from './settings';
import { Webhook } from './webhook';

/**
 * The alarm centre: every alarm and message of every machine as the gateway's watch sees them
 * (watch.ts), page open or not. A record opens when the controller raises an alarm, clears when it
 * no longer reports it, and is acknowledged by a person (who, when); a machine going offline during
 * a job is an alarm of its own. Durable before announced: each change is in `alarms.journal`
 * (alarm-files.ts) before the pages, the webhook, the audit or the log learn of it.
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
  /** Records changed and events to announce since the last `commit()`. */
  private readonly dirty = new Set<AlarmRecord>();
  private readonly pending: Array<[AlarmEvent, AlarmRecord]> = [];
  private readonly now: () => number;
  /** `alarms.json` and `alarms.journal` (alarm-files.ts). */
  private readonly files: AlarmFiles;

  constructor(private readonly opts: AlarmCentreOptions) {
    this.now = opts.now ?? Date.now;
    this.files = new AlarmFiles(opts.dataDir, opts.log, this.now, () => ({
      seq: this.seq,
      records: this.records,
    }));
    const loaded = this.files.load();
    this.records = loaded.records;
    this.seq = loaded.seq;
    if (loaded.replayed > 0) {
      this.version++;
      this.files.scheduleWrite();
    }
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
      this.files.append(records);
    }
    const events = this.pending.splice(0);
    for (const [event, r] of events) this.opts.onChange?.(event, r);
  }

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
    this.files.scheduleWrite();
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

  /** Writes what is pending now (shutdown). */
  close(): Promise<void> {
    return this.files.close();
  }

  /** For a synchronous shutdown path: writes at once. */
  flushSync(): void {
    this.files.flushSync();
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
