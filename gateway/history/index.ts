import { join } from 'node:path';
import type { WatchSummary } from '../../src/fleet/contract';
import type { AuditEntry } from '../audit';
import type { Logger } from '../log';
import type { MachineEntry } from '../machines';
import type { Retention, SettingsStore, Shift } from '../settings';
import { HistoryReads } from './reads';
import type { Families } from '../options';
import type { StatsPuller } from '../../src/fleet/server-part';
import { HEARTBEAT_MS, HistoryStore, jobCommandsOf } from './store';

/**
 * The production history as the gateway runs it: the store (store.ts) in `<data>/history.sqlite`,
 * fed by the watch (`observe`) and by the audit records of commands (`command`), a heartbeat for
 * the last-seen times, pruning at start and daily, and what the families' server parts pull in
 * (`server.history`: TouchCut's daily statistics). If the file
 * cannot be opened the console still runs: the history API answers 503 with `problem`.
 */

export const HISTORY_FILE = 'history.sqlite';
const DAY_MS = 86_400_000;

export interface History {
  readonly store: HistoryStore | null;
  /** The API's reads, off the gateway's thread (reads.ts); null without a store. */
  readonly reads: HistoryReads | null;
  /** Why there is no store. */
  readonly problem: string | null;
  observe(m: MachineEntry, prev: WatchSummary, next: WatchSummary): void;
  /** Every audit record: the job commands a machine accepted are attributed to the job. */
  recorded(e: Omit<AuditEntry, 'time'>): void;
  /** Prunes by the retention in the settings now (start, daily, after a change). */
  prune(): void;
  /** The shifts and the retention in force (the server settings). */
  settings(): { shifts: Shift[]; retention: Retention };
  /** Pulls the controllers' missing daily statistics now (the families' pullers; their timers do it hourly). */
  pullStats(): Promise<{ stored: number; failed: number }>;
  close(): void;
}

export interface HistoryOptions {
  dataDir: string;
  log: Logger;
  now: () => number;
  machines: readonly MachineEntry[];
  settings: SettingsStore;
  /** Alarm texts and job names may echo a machine's secret. */
  scrub: (text: string) => string;
  /** The families: their job commands (`jobs`) and history parts (`server.history`). */
  families: Families;
  /** The watch's read path (proxy-http.ts `watchRead`): the controllers' statistics. */
  read: (
    m: MachineEntry,
    pathAndQuery: string,
  ) => Promise<{ status: number; body: string; gateway?: boolean }>;
  /** Timers (heartbeat, pruning, statistics); tests drive them by hand. Default true. */
  timers?: boolean;
}

export function createHistory(o: HistoryOptions): History {
  let store: HistoryStore | null = null;
  let problem: string | null = null;
  const file = join(o.dataDir, HISTORY_FILE);
  try {
    store = new HistoryStore({
      file,
      log: o.log,
      now: o.now,
      retention: () => o.settings.retention(),
      jobCommands: jobCommandsOf(o.families),
    });
  } catch (e) {
    problem = e instanceof Error ? e.message : String(e);
    o.log.error('the production history cannot be opened: the console runs without it', {
      file,
      error: problem,
    });
  }
  const statsExports = Object.values(o.families).flatMap((f) => {
    const x = f?.server?.history?.statsExport;
    return x ? [x] : [];
  });
  const reads = store ? new HistoryReads(file, o.log, statsExports) : null;
  const byId = new Map(o.machines.map((m) => [m.id, m]));
  const timers: Array<ReturnType<typeof setInterval>> = [];
  const pullers: StatsPuller[] = [];

  const pruneFailed = (e: unknown): void => {
    o.log.error('the production history could not be pruned', { error: String(e) });
  };
  /** At start, in one go; daily and after a change of the retention, a batch at a time. */
  const pruneNow = (): void => {
    try {
      store?.prune();
    } catch (e) {
      pruneFailed(e);
    }
  };
  let pruning = false;
  let again = false;
  const prune = (): void => {
    if (!store) return;
    // One at a time; asked again meanwhile (a new retention): once more after it.
    if (pruning) {
      again = true;
      return;
    }
    pruning = true;
    void store
      .pruneGently()
      .catch(pruneFailed)
      .finally(() => {
        pruning = false;
        if (again) {
          again = false;
          prune();
        }
      });
  };

  if (store) {
    const s = store;
    pruneNow();
    for (const fam of Object.values(o.families)) {
      const part = fam?.server?.history;
      if (!part) continue;
      pullers.push(
        part.statsPuller({
          days: s.statsDays(),
          machines: o.machines.filter((m) => m.kind === fam.kind),
          read: (m, p) => {
            const entry = byId.get(m.id);
            if (!entry) return Promise.reject(new Error(`no machine ${m.id}`));
            return o.read(entry, p);
          },
          log: o.log,
          now: o.now,
        }),
      );
    }
    if (o.timers !== false) {
      timers.push(
        setInterval(() => s.heartbeat(), HEARTBEAT_MS),
        setInterval(prune, DAY_MS),
      );
      for (const t of timers) t.unref();
      for (const p of pullers) p.start();
    }
  }

  return {
    store,
    reads,
    problem,
    observe(m, prev, next) {
      store?.observe(m, prev, {
        ...next,
        alarm: next.alarm === null ? null : o.scrub(next.alarm),
        job: next.job === null ? null : o.scrub(next.job),
      });
    },
    recorded(e) {
      if (e.type !== 'command' || e.result !== 'ok' || !e.machine) return;
      const who = e.onBehalfOf ? `${e.user} (on ${e.onBehalfOf}'s tablet)` : e.user;
      store?.command(e.machine, e.commandId, who);
    },
    prune,
    settings: () => ({ shifts: o.settings.shifts(), retention: o.settings.retention() }),
    pullStats: async () => {
      let stored = 0;
      let failed = 0;
      for (const p of pullers) {
        const r = await p.pullOnce();
        stored += r.stored;
        failed += r.failed;
      }
      return { stored, failed };
    },
    close() {
      for (const t of timers) clearInterval(t);
      for (const p of pullers) p.stop();
      reads?.close();
      try {
        store?.close();
      } catch (e) {
        o.log.error('the production history could not be closed', { error: String(e) });
      }
    },
  };
}
