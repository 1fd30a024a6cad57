import { addDays, localDay } from '../../../../gateway/history/shifts';
import type { HistoryDays, PartLog } from '../../../fleet/server-part';
import { statsSchema } from '../wire';

interface HistoryMachine {
  id: string;
  name: string;
  kind: string;
}

/**
 * TouchCut's own production statistics, pulled into the history store one completed day at a time
 * (`GET rest/v1/stats?start-date=D&end-before-date=D+1&units=metric`, through the same path as
 * the watch: the machine's API key or held login), so they outlive the controller's logging range.
 * Each day is stored once, as the controller returned it (parsed as JSON, checked against the
 * console's stats schema: an answer the schema refuses is not stored). Days are the server's
 * local calendar days. A machine that does not answer is tried again at the next pull (hourly);
 * its failure is logged once a day.
 */

export const PULL_EVERY_MS = 60 * 60_000;
/** The first pull after the server starts (the watch has seen the machines by then). */
export const FIRST_PULL_MS = 60_000;
/** How many completed days back a pull fills (a new machine, a console that was off). */
export const BACKFILL_DAYS = 14;
const MAX_BODY = 2 * 1024 * 1024;

export type StatsRead = (
  m: HistoryMachine,
  pathAndQuery: string,
) => Promise<{ status: number; body: string; gateway?: boolean }>;

export interface TouchcutStatsOptions {
  /** The history's days of statistics (`touchcut_days`). */
  days: HistoryDays;
  machines: readonly HistoryMachine[];
  read: StatsRead;
  log: PartLog;
  now?: () => number;
  backfillDays?: number;
}

export class TouchcutStatsPuller {
  private timer: ReturnType<typeof setTimeout> | null = null;
  private running: Promise<unknown> | null = null;
  private readonly failedOn = new Map<string, string>();
  private stopped = false;

  constructor(private readonly o: TouchcutStatsOptions) {}

  /** Pulls every missing completed day of every TouchCut machine. */
  async pullOnce(): Promise<{ stored: number; failed: number }> {
    let stored = 0;
    let failed = 0;
    const now = this.o.now ?? Date.now;
    for (const m of this.o.machines) {
      if (this.stopped || this.o.days.isClosed) break;
      const today = localDay(now());
      const first = addDays(today, -(this.o.backfillDays ?? BACKFILL_DAYS));
      const held = this.o.days.held(m.id, first);
      for (let day = first; day < today; day = addDays(day, 1)) {
        if (held.has(day)) continue;
        const problem = await this.pullDay(m, day, now);
        if (this.stopped || this.o.days.isClosed) break;
        if (problem) {
          failed++;
          if (this.failedOn.get(m.id) !== today) {
            this.failedOn.set(m.id, today);
            this.o.log.warn(`${m.id}: TouchCut statistics not pulled: ${problem}`, { machine: m.id, day });
          }
          break; // the next pull tries again
        }
        stored++;
      }
    }
    return { stored, failed };
  }

  /** One day: null when stored, else what went wrong. */
  private async pullDay(m: HistoryMachine, day: string, now: () => number): Promise<string | null> {
    const q = new URLSearchParams({ 'start-date': day, 'end-before-date': addDays(day, 1), units: 'metric' });
    let a: { status: number; body: string; gateway?: boolean };
    try {
      a = await this.o.read(m, `/rest/v1/stats?${q.toString()}`);
    } catch (e) {
      return e instanceof Error ? e.message : String(e);
    }
    if (a.gateway) return 'the machine cannot be reached';
    if (a.status !== 200) return `rest/v1/stats answered ${a.status}`;
    if (a.body.length > MAX_BODY) return 'the answer is too large';
    let json: unknown;
    try {
      json = JSON.parse(a.body);
    } catch {
      return 'rest/v1/stats: not JSON';
    }
    const valid = statsSchema.safeParse(json);
    if (!valid.success) {
      const i = valid.error.issues[0];
      return `rest/v1/stats: ${i ? `${i.path.join('.')}: ${i.message}` : 'invalid'}`;
    }
    if (this.o.days.isClosed) return 'the history store is closed';
    this.o.days.put(m.id, day, json, now());
    return null;
  }

  start(): void {
    if (!this.o.machines.length) return;
    this.schedule(FIRST_PULL_MS);
  }

  private schedule(ms: number): void {
    if (this.stopped) return;
    this.timer = setTimeout(() => {
      this.timer = null;
      this.running = this.pullOnce()
        .catch((e: unknown) => this.o.log.error('TouchCut statistics pull failed', { error: String(e) }))
        .finally(() => {
          this.running = null;
          this.schedule(PULL_EVERY_MS);
        });
    }, ms);
    this.timer.unref?.();
  }

  stop(): void {
    this.stopped = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
  }

  /** A pull in progress (tests, shutdown). */
  get busy(): Promise<unknown> | null {
    return this.running;
  }
}
